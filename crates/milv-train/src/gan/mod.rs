//! A-CycleGAN with inverse dynamics (paper section 4.1, Appendix A.2): the networks, their
//! losses and step, the data they train on, the training loop, checkpoints, translation
//! of human episodes into the `imagined` table, and translation quality.

pub mod checkpoint;
pub mod config;
pub mod cyclegan;
pub mod data;
pub mod eval;
pub mod nets;
pub mod pool;
pub mod train;
pub mod translate;

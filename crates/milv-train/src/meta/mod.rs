//! DAML / MILV meta-policies (paper section 4.2): the policy and its second-order meta
//! step, the per-task sequences of each variant, the meta-training loop and policy
//! checkpoints, one-shot evaluation in milv-sim, and the check that a translator's
//! imagined actions are worth imitating ([`check`]).

pub mod check;
pub mod oneshot;
pub mod policy;
pub mod tasks;
pub mod train;

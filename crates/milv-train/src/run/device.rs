//! Where the networks run.

use tch::Device;

/// `cpu`, `cuda` (the first GPU; an error without one) or `auto` (CUDA when available).
pub fn parse(s: &str) -> Result<Device, crate::Error> {
    match s {
        "cpu" => Ok(Device::Cpu),
        "cuda" if tch::Cuda::is_available() => Ok(Device::Cuda(0)),
        "cuda" => Err(crate::Error::Config(
            "--device cuda, but libtorch sees no CUDA device (is the CUDA build of torch installed?)".into(),
        )),
        "auto" => Ok(Device::cuda_if_available()),
        _ => Err(crate::Error::Config(format!(
            "unknown device {s:?} (cpu | cuda | auto)"
        ))),
    }
}

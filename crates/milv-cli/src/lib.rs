//! # milv-cli — what the command-line tools share: exit codes, progress bars, output helpers

use indicatif::{ProgressBar, ProgressStyle};

/// Exit code when every input went through.
pub const EXIT_OK: u8 = 0;
/// Exit code for a fatal error (nothing was committed).
pub const EXIT_FATAL: u8 = 1;
/// Exit code when some inputs failed and the others landed.
pub const EXIT_PARTIAL: u8 = 3;

/// A progress bar on stderr; indicatif draws nothing when stderr is not a terminal, so
/// piped and CI output stays clean.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    let style =
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} {msg} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar());
    pb.set_style(style);
    pb.set_message(what.to_string());
    pb
}

/// Prints a value as pretty JSON on stdout.
pub fn print_json<T: serde::Serialize>(v: &T) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(v)?);
    Ok(())
}

/// Formats a byte count for people.
pub fn human_bytes(n: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = n as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{n} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// Turns a tool's result into its exit code, printing a fatal error as `TOOL: error: …`.
/// A closed stdout (`milv-… | head`) is not an error.
pub fn finish(tool: &str, result: anyhow::Result<u8>) -> std::process::ExitCode {
    match result {
        Ok(code) => std::process::ExitCode::from(code),
        Err(e)
            if e.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            std::process::ExitCode::from(EXIT_OK)
        }
        Err(e) => {
            eprintln!("{tool}: error: {e:#}");
            std::process::ExitCode::from(EXIT_FATAL)
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn bytes_read_well() {
        assert_eq!(super::human_bytes(12), "12 B");
        assert_eq!(super::human_bytes(3 << 20), "3.0 MiB");
    }
}

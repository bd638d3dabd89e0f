//! Every cap the program enforces, in one place, so that a hostile or mistyped parameter is
//! refused with a message naming it instead of exhausting memory or threads. The README's
//! "Limits" section lists these; each says how to raise it.

use crate::error::{Error, Result};

/// Most worker threads a run or render may ask for. More than a few per core only adds
/// scheduling overhead; a typo such as `--threads 18446744073709551615` must not start 15,000.
pub const MAX_THREADS: usize = 1024;

/// Environment variable that sets the memory limit when `--max-memory` is not given.
pub const MEMORY_ENV: &str = "FIREFLIES_MAX_MEMORY";

/// Fallback limit when the machine's memory cannot be read.
const FALLBACK_MEMORY: u64 = 16 << 30;

/// Checks a requested worker-thread count (`None` or 0: one per core).
pub fn threads(requested: Option<usize>) -> Result<usize> {
    match requested {
        Some(n) if n > MAX_THREADS => Err(Error::param(
            "threads",
            n,
            format!("at most {MAX_THREADS} (0 or omitted: one per core)"),
        )),
        Some(n) => Ok(n),
        None => Ok(0),
    }
}

/// A rayon pool of `threads` workers (0: one per core), as every command that parallelises
/// builds it; its error names the parameter.
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::param("threads", threads, e.to_string()))
}

/// The most memory a run or render may plan to hold, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryLimit(pub u64);

impl Default for MemoryLimit {
    /// Three quarters of the machine's physical memory: past that, the run would swap or be
    /// killed anyway, and the rest of the machine keeps room to work.
    fn default() -> Self {
        MemoryLimit(physical_memory().map_or(FALLBACK_MEMORY, |m| m / 4 * 3))
    }
}

impl MemoryLimit {
    /// From `--max-memory` if given, else from [`MEMORY_ENV`] if set, else the default.
    pub fn from_setting(flag: Option<&str>) -> Result<Self> {
        if let Some(text) = flag {
            return Self::parse("max-memory", text);
        }
        match std::env::var(MEMORY_ENV) {
            Ok(text) => Self::parse(MEMORY_ENV, &text),
            Err(_) => Ok(Self::default()),
        }
    }

    /// Parses a size such as `512MiB`, `24GiB`, `1.5T` or a plain byte count. Units are
    /// binary (`K`, `M`, `G`, `T`, with or without `iB`/`B`).
    pub fn parse(name: &'static str, text: &str) -> Result<Self> {
        let bad = || {
            Error::param(
                name,
                shorten(text),
                "expected a size such as 4096, 512MiB, 24GiB or 1.5T",
            )
        };
        let t = text.trim();
        let split = t
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(t.len());
        let (number, unit) = t.split_at(split);
        let value: f64 = number.parse().map_err(|_| bad())?;
        let shift = match unit.trim().to_ascii_lowercase().as_str() {
            "" | "b" => 0,
            "k" | "kb" | "kib" => 10,
            "m" | "mb" | "mib" => 20,
            "g" | "gb" | "gib" => 30,
            "t" | "tb" | "tib" => 40,
            _ => return Err(bad()),
        };
        let bytes = value * (1u64 << shift) as f64;
        if !(bytes >= 1.0 && bytes < u64::MAX as f64) {
            return Err(Error::param(
                name,
                shorten(text),
                "must be at least 1 byte and below 16 EiB",
            ));
        }
        Ok(MemoryLimit(bytes as u64))
    }

    /// Refuses a plan that would hold `needed` bytes (a lower bound), naming what set it.
    pub fn check(self, parameter: impl Into<String>, needed: u128) -> Result<()> {
        if needed > u128::from(self.0) {
            return Err(Error::MemoryLimit {
                parameter: parameter.into(),
                needed,
                limit: self.0,
            });
        }
        Ok(())
    }
}

/// The process's peak resident memory (`VmHWM` in `/proc/self/status`, Linux); `None`
/// elsewhere. Reported by long commands so that memory claims are measured, not estimated.
pub fn peak_rss_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Physical memory from `/proc/meminfo` (Linux); `None` elsewhere.
fn physical_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// At most 40 characters of user input, for messages.
pub fn shorten(text: &str) -> String {
    const KEEP: usize = 40;
    let escaped: String = text.escape_debug().collect();
    if escaped.chars().count() <= KEEP {
        escaped
    } else {
        let head: String = escaped.chars().take(KEEP).collect();
        format!("{head}... ({} bytes)", text.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_in_binary_units_and_bad_ones_are_named() {
        assert_eq!(MemoryLimit::parse("m", "4096").unwrap().0, 4096);
        assert_eq!(MemoryLimit::parse("m", "512MiB").unwrap().0, 512 << 20);
        assert_eq!(MemoryLimit::parse("m", "1.5T").unwrap().0, 3 << 39);
        assert_eq!(MemoryLimit::parse("m", " 24 gb ").unwrap().0, 24 << 30);
        for bad in [
            "",
            "G",
            "-1G",
            "0",
            "1e3",
            "12 parsecs",
            "99999999999T",
            "nan",
        ] {
            let e = MemoryLimit::parse("max-memory", bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains("max-memory"), "{bad}: {e}");
        }
    }

    #[test]
    fn plans_above_the_limit_are_refused_with_both_sizes() {
        let limit = MemoryLimit(1 << 30);
        assert!(limit.check("x", 1 << 30).is_ok());
        let e = limit
            .check("trials = 7", (1 << 30) + 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("trials = 7") && e.contains("1.0 GiB") && e.contains("--max-memory"));
    }

    #[test]
    fn thread_counts_are_capped() {
        assert_eq!(threads(None).unwrap(), 0);
        assert_eq!(threads(Some(MAX_THREADS)).unwrap(), MAX_THREADS);
        let e = threads(Some(usize::MAX)).unwrap_err().to_string();
        assert!(e.contains("threads") && e.contains("1024"), "{e}");
    }

    #[test]
    fn long_input_is_shortened_and_escaped() {
        assert_eq!(shorten("a\0b"), "a\\0b");
        let long = "x".repeat(1000);
        let s = shorten(&long);
        assert!(
            s.starts_with(&"x".repeat(40)) && s.ends_with("(1000 bytes)"),
            "{s}"
        );
    }
}

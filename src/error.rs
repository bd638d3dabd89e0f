//! The one error type of the crate. Every variant carries the offending name, index or value,
//! because a failure seen once in a million trials must be diagnosable from its message alone.

use std::fmt;

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in `fireflies`, each case naming what was wrong and its value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// A constructor parameter is out of its domain.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name as written in spec strings (`M`, `threshold`, `kappa`...).
        name: &'static str,
        /// The rejected value, printed as given.
        value: String,
        /// What the parameter must satisfy.
        reason: String,
    },
    /// A sample that is NaN, infinite or negative.
    #[error("invalid sample at index {index}: {}", Num(*value))]
    InvalidSample {
        /// Position of the sample in its stream (0-based).
        index: u64,
        /// The sample itself.
        value: f64,
    },
    /// An estimate or statistic was requested from a stream with no samples.
    #[error("empty stream: {0} has no samples")]
    EmptyStream(String),
    /// A spec string names an estimator that does not exist.
    #[error("unknown estimator '{name}'; valid names: {valid}")]
    UnknownEstimator {
        /// The name given.
        name: String,
        /// Comma-separated list of valid names.
        valid: String,
    },
    /// A spec string uses a key the estimator does not take.
    #[error("unknown key '{key}' for estimator '{estimator}'; valid keys: {valid}")]
    UnknownKey {
        /// Estimator name.
        estimator: String,
        /// The key given.
        key: String,
        /// Comma-separated list of valid keys.
        valid: String,
    },
    /// A spec string is not of the form `name[:key=value,...]`, repeats a key, omits a
    /// required one or gives a value that is not a number of the right kind.
    #[error("malformed estimator spec '{spec}': {reason}")]
    MalformedSpec {
        /// The whole spec string.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A mixture component is rejected (for example an untruncated Pareto with shape <= 1,
    /// whose mean is infinite so that bias is undefined).
    #[error("mixture component {component}: {reason}")]
    Component {
        /// Index of the component in the mixture (0-based).
        component: usize,
        /// What is wrong with it, naming the parameter and its value.
        reason: String,
    },
    /// A scene file (Mitsuba 3 XML subset) that cannot be loaded: unknown or misspelt element,
    /// plugin or parameter, a malformed or out-of-range value, a missing required element, or an
    /// unreadable referenced file.
    #[error("{file}:{line}: <{element}>: {message}")]
    Scene {
        /// Scene file name as given to the loader.
        file: String,
        /// 1-based line of the offending element.
        line: u32,
        /// The element: its tag and its `type`, `name` or `id` attribute, e.g.
        /// `shape type="sphere"` or `float name="alpha"`.
        element: String,
        /// What is wrong, naming the offending value.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {message}")]
    Io {
        /// Path of the file.
        path: String,
        /// The operating system's message.
        message: String,
    },
    /// A run or render would hold more memory than the limit allows; refused before allocating.
    #[error(
        "{parameter}: needs at least {} of memory, above the limit of {} \
         (raise it with --max-memory or the FIREFLIES_MAX_MEMORY environment variable)",
        Bytes(*needed),
        Bytes(*limit)
    )]
    MemoryLimit {
        /// The parameter (or parameters) that set the size, with their values.
        parameter: String,
        /// Bytes the run would hold, a lower bound.
        needed: u128,
        /// The limit in bytes.
        limit: u64,
    },
    /// An experiment file whose content is rejected; the message names the entry at fault.
    #[error("{file}: {message}")]
    Experiment {
        /// The experiment file as given (or the embedded default's name).
        file: String,
        /// The entry (e.g. `estimators[2] = "mon:M=0"`) and what is wrong with it.
        message: String,
    },
    /// Text in a sample file that cannot be read as samples: a malformed or over-long token, a
    /// NUL byte, invalid UTF-8, or a number that is not a valid sample (NaN, infinite or
    /// negative). `problem` quotes at most about 40 characters of the input, with control and
    /// other invisible characters escaped (`\0`, `\u{feff}`).
    #[error("{file}:{line}: {problem} (column {column})")]
    SampleText {
        /// File name (`-` for stdin).
        file: String,
        /// 1-based line number.
        line: usize,
        /// 1-based column, counted in characters (Unicode scalar values).
        column: usize,
        /// What is wrong, quoting the offending input.
        problem: String,
    },
}

impl Error {
    /// Shorthand for [`Error::InvalidParameter`]; floats print in short form ([`Num`]).
    pub fn param(name: &'static str, value: impl ParamValue, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name,
            value: value.text(),
            reason: reason.into(),
        }
    }

    /// Shorthand for [`Error::Io`] from an `std::io::Error`.
    pub fn io(path: impl fmt::Display, err: &std::io::Error) -> Self {
        Error::Io {
            path: path.to_string(),
            message: err.to_string(),
        }
    }
}

/// A parameter value as a message shows it. Floats go through [`Num`], so that no message
/// prints `1e308` as 309 digits; everything else prints as it displays.
pub trait ParamValue {
    /// The value's text in a message.
    fn text(&self) -> String;
}

impl ParamValue for f64 {
    fn text(&self) -> String {
        Num(*self).to_string()
    }
}

impl ParamValue for f32 {
    fn text(&self) -> String {
        Num::from_f32(*self).to_string()
    }
}

macro_rules! display_param_value {
    ($($t:ty),*) => {$(
        impl ParamValue for $t {
            fn text(&self) -> String {
                self.to_string()
            }
        }
    )*};
}
display_param_value!(
    u8,
    u16,
    u32,
    u64,
    u128,
    usize,
    i8,
    i16,
    i32,
    i64,
    i128,
    isize,
    str,
    String,
    Num,
    std::path::Display<'_>
);

impl<T: ParamValue + ?Sized> ParamValue for &T {
    fn text(&self) -> String {
        (**self).text()
    }
}

/// A number as people read it in messages, labels and summaries: the shortest decimal that
/// round-trips, switching to scientific notation outside `[1e-4, 1e16)` so that `1e308` never
/// prints as 309 digits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl Num {
    /// An f32 through its own shortest decimal, so `0.1f32` prints as `0.1`, not as the f64
    /// `0.10000000149011612`.
    pub fn from_f32(x: f32) -> Self {
        Num(x.to_string().parse().unwrap_or(f64::from(x)))
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        let magnitude = x.abs();
        if !x.is_finite() || x == 0.0 || (1e-4..1e16).contains(&magnitude) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

/// A byte count in binary units (`1.5 GiB`), for messages about memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bytes<T>(pub T);

impl<T: Copy + Into<u128>> fmt::Display for Bytes<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bytes: u128 = self.0.into();
        const UNITS: [&str; 7] = ["KiB", "MiB", "GiB", "TiB", "PiB", "EiB", "ZiB"];
        if bytes < 1024 {
            return write!(f, "{bytes} B");
        }
        let mut value = bytes as f64 / 1024.0;
        let mut unit = 0;
        while value >= 1024.0 && unit + 1 < UNITS.len() {
            value /= 1024.0;
            unit += 1;
        }
        write!(f, "{value:.1} {}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::{Bytes, Num};

    #[test]
    fn byte_counts_print_in_binary_units() {
        assert_eq!(Bytes(512u64).to_string(), "512 B");
        assert_eq!(Bytes(1536u64).to_string(), "1.5 KiB");
        assert_eq!(Bytes(24u64 << 30).to_string(), "24.0 GiB");
        assert!(Bytes(u128::MAX).to_string().ends_with(" ZiB"));
    }

    #[test]
    fn numbers_print_short_and_round_trip() {
        let cases = [
            (1e308, "1e308"),
            (f64::MAX, "1.7976931348623157e308"),
            (5e-324, "5e-324"),
            (0.1, "0.1"),
            (-2.5, "-2.5"),
            (1234567.0, "1234567"),
            (1e16, "1e16"),
            (0.0, "0"),
            (f64::NAN, "NaN"),
            (f64::NEG_INFINITY, "-inf"),
        ];
        for (x, text) in cases {
            assert_eq!(Num(x).to_string(), text);
            if x.is_finite() {
                assert_eq!(text.parse::<f64>().unwrap(), x);
            }
        }
    }
}

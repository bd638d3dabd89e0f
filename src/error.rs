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
    #[error("invalid sample at index {index}: {value}")]
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
    /// A token in a sample file that is not a decimal number.
    #[error("{file}:{line}: malformed number '{token}'")]
    MalformedNumber {
        /// File name (`-` for stdin).
        file: String,
        /// 1-based line number.
        line: usize,
        /// The offending token.
        token: String,
    },
    /// A number in a sample file that is not a valid sample (NaN, infinite or negative).
    #[error("{file}:{line}: invalid sample at index {index}: {value}")]
    InvalidSampleInFile {
        /// File name (`-` for stdin).
        file: String,
        /// 1-based line number.
        line: usize,
        /// Position of the sample in the file's stream (0-based).
        index: u64,
        /// The sample itself.
        value: f64,
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
}

impl Error {
    /// Shorthand for [`Error::InvalidParameter`] with any displayable value.
    pub fn param(name: &'static str, value: impl fmt::Display, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name,
            value: value.to_string(),
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

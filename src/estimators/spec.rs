//! Spec strings `name[:key=value,...]` (docs/estimators.md §1a) and their structured form.
//!
//! Each method declares itself once, in its own file, by implementing [`Method`] on its spec
//! type: its name, its keys (type, default, required or not), whether it is constant-memory and
//! how it builds its scalar and RGB estimators. The one list of methods, [`methods!`] in
//! `estimators/mod.rs`, turns those declarations into [`EstimatorSpec`] and everything it does:
//! parsing, canonical printing, the valid-name list in errors, defaults and construction.
//!
//! Parsing is strict: unknown names and keys list the valid ones, a repeated key or a missing
//! required key is an error, and integer keys take integer literals only. Printing gives the
//! canonical form (every key in declared order, floats in shortest round-trip form), and parsing
//! the printed form gives the same spec back. Ranges are checked when the estimator is built.

use super::{Estimator, EstimatorSpec, RgbEstimator};
use crate::error::{Error, Result};
use std::fmt;

/// How many buffers Zirr's cascade has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CascadeSize {
    /// Grow on demand so no sample lies above the top buffer (docs/estimators.md §5, default for `zirr`).
    Auto,
    /// The paper's literal fixed cascade of J buffers.
    Fixed(usize),
}

/// Every constant-memory estimator at the parameters a user would start from: the set the
/// benchmarks and speed goals measure as "a Bank of all constant-memory estimators".
pub const CONSTANT_MEMORY_SET: [&str; 9] = [
    "mean",
    "clamp:c=10",
    "mon:M=21",
    "gini:M=21",
    "gmonb:M=21",
    "gmon:M=21",
    "jung:sigma_image=1",
    "zirr",
    "zirr-ref",
];

/// One estimator method as spec strings name it, implemented by the method's spec type (the
/// payload of its [`EstimatorSpec`] variant) in the method's own file.
pub trait Method: Copy + PartialEq + fmt::Debug + Into<EstimatorSpec> + 'static {
    /// The name in spec strings.
    const NAME: &'static str;
    /// Every key, in canonical (printing) order.
    const KEYS: &'static [Key<Self>];
    /// Every optional key at its default; required keys are overwritten by parsing.
    const DEFAULT: Self;
    /// Whether the per-pixel memory is bounded independently of the stream.
    const CONSTANT_MEMORY: bool = true;

    /// Builds the scalar estimator, checking every parameter.
    fn build(&self) -> Result<Box<dyn Estimator>>;

    /// Builds the RGB estimator (docs in `rgb.rs`), checking every parameter as `build` does.
    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>>;
}

/// One key of a method: its name, whether it must be given, and the spec field it reads and
/// writes (whose type is the key's type).
pub struct Key<S> {
    name: &'static str,
    required: bool,
    field: Field<S>,
}

/// A key's field and type.
enum Field<S> {
    /// A float (any `f64` literal).
    Float(fn(&mut S) -> &mut f64),
    /// A non-negative integer literal.
    Int(fn(&mut S) -> &mut usize),
    /// A cascade size: an integer literal, or `auto` when `auto` is set.
    Cascade {
        auto: bool,
        at: fn(&mut S) -> &mut CascadeSize,
    },
}

impl<S> Key<S> {
    /// A float key, defaulting to the field's value in [`Method::DEFAULT`].
    pub const fn float(name: &'static str, at: fn(&mut S) -> &mut f64) -> Self {
        Key {
            name,
            required: false,
            field: Field::Float(at),
        }
    }

    /// An integer-literal key, defaulting to the field's value in [`Method::DEFAULT`].
    pub const fn int(name: &'static str, at: fn(&mut S) -> &mut usize) -> Self {
        Key {
            name,
            required: false,
            field: Field::Int(at),
        }
    }

    /// A cascade-size key (`auto` accepted only when `auto` is true).
    pub const fn cascade(
        name: &'static str,
        auto: bool,
        at: fn(&mut S) -> &mut CascadeSize,
    ) -> Self {
        Key {
            name,
            required: false,
            field: Field::Cascade { auto, at },
        }
    }

    /// `key` with no default: a spec must give it.
    pub const fn required(self) -> Self {
        Key {
            required: true,
            ..self
        }
    }

    /// The key's name as written in spec strings.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Writes the key's value in `spec` in canonical form.
    fn write(&self, spec: &S, f: &mut fmt::Formatter<'_>) -> fmt::Result
    where
        S: Copy,
    {
        let mut s = *spec;
        match self.field {
            Field::Float(at) => write!(f, "{}", fmt_f64(*at(&mut s))),
            Field::Int(at) => write!(f, "{}", at(&mut s)),
            Field::Cascade { at, .. } => match *at(&mut s) {
                CascadeSize::Auto => write!(f, "auto"),
                CascadeSize::Fixed(j) => write!(f, "{j}"),
            },
        }
    }

    /// Parses `v` into the key's field of `spec`.
    fn read(&self, spec: &mut S, v: &str, text: &str) -> Result<()> {
        let key = self.name;
        let bad = |what: &str| malformed(text, format!("{key} = '{v}' is not {what}"));
        match self.field {
            Field::Float(at) => *at(spec) = v.parse().map_err(|_| bad("a number"))?,
            Field::Int(at) => *at(spec) = parse_int(v).ok_or_else(|| bad("an integer literal"))?,
            Field::Cascade { auto: true, at } if v == "auto" => *at(spec) = CascadeSize::Auto,
            Field::Cascade { auto, at } => {
                let what = if auto {
                    "an integer literal or 'auto'"
                } else {
                    "an integer literal"
                };
                *at(spec) = CascadeSize::Fixed(parse_int(v).ok_or_else(|| bad(what))?);
            }
        }
        Ok(())
    }
}

/// The one list of methods: one line `Variant(module::SpecType),` per method, in the order the
/// valid-name list shows them. Generates [`EstimatorSpec`], with a variant per method holding
/// its spec type, and its dispatch to each method's [`Method`] declaration.
macro_rules! methods {
    ($($variant:ident($module:ident::$spec:ident),)*) => {
        $(pub use $module::$spec;)*

        /// The structured form of a spec string: which estimator, with every parameter explicit.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub enum EstimatorSpec {
            $(
                #[doc = concat!("See [`", stringify!($spec), "`].")]
                $variant($spec),
            )*
        }

        $(
            impl From<$spec> for EstimatorSpec {
                fn from(s: $spec) -> Self {
                    EstimatorSpec::$variant(s)
                }
            }
        )*

        impl EstimatorSpec {
            /// Every valid estimator name, in the list's order.
            pub fn names() -> impl Iterator<Item = &'static str> {
                [$(<$spec as spec::Method>::NAME),*].into_iter()
            }

            /// The estimator's name as written in spec strings.
            pub fn name(&self) -> &'static str {
                match self {
                    $(EstimatorSpec::$variant(_) => <$spec as spec::Method>::NAME,)*
                }
            }

            /// Whether the method's per-pixel memory is bounded independently of the stream
            /// (everything but Pajot's learning set and dubious list).
            pub fn is_constant_memory(&self) -> bool {
                match self {
                    $(EstimatorSpec::$variant(_) => <$spec as spec::Method>::CONSTANT_MEMORY,)*
                }
            }

            /// Builds the estimator, checking every parameter.
            pub fn build(&self) -> Result<Box<dyn Estimator>> {
                match self {
                    $(EstimatorSpec::$variant(s) => spec::Method::build(s),)*
                }
            }

            /// Builds the RGB estimator, checking every parameter as
            /// [`EstimatorSpec::build`] does.
            pub fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
                match self {
                    $(EstimatorSpec::$variant(s) => spec::Method::build_rgb(s),)*
                }
            }
        }

        impl std::fmt::Display for EstimatorSpec {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                match self {
                    $(EstimatorSpec::$variant(s) => spec::write_spec(s, f),)*
                }
            }
        }

        impl std::str::FromStr for EstimatorSpec {
            type Err = crate::error::Error;

            fn from_str(text: &str) -> Result<Self> {
                let (name, rest) = spec::split_name(text);
                $(
                    if name == <$spec as spec::Method>::NAME {
                        return spec::parse_spec::<$spec>(text, rest).map(EstimatorSpec::$variant);
                    }
                )*
                Err(spec::unknown_name(name, Self::names()))
            }
        }
    };
}
pub(super) use methods;

/// Shortest round-trip text of a float; exponent form when the plain form would be long
/// (`1e300`, not three hundred digits).
pub(super) fn fmt_f64(x: f64) -> String {
    let plain = format!("{x}");
    if plain.len() > 18 {
        format!("{x:e}")
    } else {
        plain
    }
}

/// `name:key=value,...` with every key in declared order.
pub(super) fn write_spec<M: Method>(spec: &M, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    write!(f, "{}", M::NAME)?;
    for (i, key) in M::KEYS.iter().enumerate() {
        write!(f, "{}{}=", if i == 0 { ':' } else { ',' }, key.name)?;
        key.write(spec, f)?;
    }
    Ok(())
}

/// The name (trimmed) and the text after its `:`, if any.
pub(super) fn split_name(text: &str) -> (&str, Option<&str>) {
    match text.split_once(':') {
        Some((n, r)) => (n.trim(), Some(r)),
        None => (text.trim(), None),
    }
}

/// The error for a name no method has, listing the valid ones.
pub(super) fn unknown_name<'a>(name: &str, valid: impl Iterator<Item = &'a str>) -> Error {
    Error::UnknownEstimator {
        name: name.to_string(),
        valid: valid.collect::<Vec<_>>().join(", "),
    }
}

fn malformed(text: &str, reason: impl Into<String>) -> Error {
    Error::MalformedSpec {
        spec: text.to_string(),
        reason: reason.into(),
    }
}

/// Parses the `key=value` list `rest` of method `M`'s spec `text`: known keys only, each at
/// most once, every required key present; the others keep [`Method::DEFAULT`]'s values.
pub(super) fn parse_spec<M: Method>(text: &str, rest: Option<&str>) -> Result<M> {
    let mut pairs: Vec<(&Key<M>, &str)> = Vec::new();
    for item in rest.into_iter().flat_map(|r| r.split(',')) {
        let Some((k, v)) = item.split_once('=') else {
            return Err(malformed(text, format!("'{item}' is not key=value")));
        };
        let (k, v) = (k.trim(), v.trim());
        let Some(key) = M::KEYS.iter().find(|key| key.name == k) else {
            let valid = if M::KEYS.is_empty() {
                "(none)".to_string()
            } else {
                M::KEYS
                    .iter()
                    .map(|k| k.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            return Err(Error::UnknownKey {
                estimator: M::NAME.to_string(),
                key: k.to_string(),
                valid,
            });
        };
        if pairs.iter().any(|(seen, _)| seen.name == k) {
            return Err(malformed(text, format!("key '{k}' given twice")));
        }
        pairs.push((key, v));
    }
    let mut spec = M::DEFAULT;
    for key in M::KEYS {
        match pairs.iter().find(|(k, _)| k.name == key.name) {
            Some((_, v)) => key.read(&mut spec, v, text)?,
            None if key.required => {
                return Err(malformed(
                    text,
                    format!("missing required key '{}'", key.name),
                ));
            }
            None => {}
        }
    }
    Ok(spec)
}

/// A non-negative decimal integer literal (`5`, not `5.0` or `+5`).
fn parse_int(v: &str) -> Option<usize> {
    if v.is_empty() || !v.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    v.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_forms_round_trip() {
        for s in [
            "mean",
            "clamp:c=10",
            "mon:M=21",
            "gini:M=21",
            "gmonb:M=21,threshold=0.25",
            "gmon:M=21",
            "jung:sigma_image=0.5,m_max=17",
            "zirr:b=8,J=auto,kappa=1,kappa_min=1,u=1",
            "zirr:b=8,J=6,kappa=1,kappa_min=1,u=1",
            "zirr-ref:b=8,J=6,kappa=32,kappa_min=1,u=1",
            "pajot-rot:learn=50",
            "pajot-adr:learn=50",
            "pajot-hybrid:learn=50,T=2,delta=0",
            "clamp:c=1e300",
            "clamp:c=1e-300",
        ] {
            let spec: EstimatorSpec = s.parse().unwrap();
            assert_eq!(spec.to_string(), s);
        }
    }

    #[test]
    fn defaults_fill_omitted_keys_in_any_order() {
        let s: EstimatorSpec = "zirr:kappa=4,b=2".parse().unwrap();
        assert_eq!(s.to_string(), "zirr:b=2,J=auto,kappa=4,kappa_min=1,u=1");
        let s: EstimatorSpec = "zirr-ref:kappa=32".parse().unwrap();
        assert_eq!(s.to_string(), "zirr-ref:b=8,J=6,kappa=32,kappa_min=1,u=1");
        let s: EstimatorSpec = "gmonb:M=21".parse().unwrap();
        assert_eq!(s.to_string(), "gmonb:M=21,threshold=0.25");
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let e = "median".parse::<EstimatorSpec>().unwrap_err().to_string();
        assert!(
            e.contains("'median'") && e.contains("gmonb") && e.contains("pajot-hybrid"),
            "{e}"
        );
        let e = "mon:N=3".parse::<EstimatorSpec>().unwrap_err().to_string();
        assert!(e.contains("'N'") && e.contains("valid keys: M"), "{e}");
        let e = "mon:M=5.0"
            .parse::<EstimatorSpec>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("integer literal"), "{e}");
        let e = "mon:M=3,M=5"
            .parse::<EstimatorSpec>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("twice"), "{e}");
        let e = "mon".parse::<EstimatorSpec>().unwrap_err().to_string();
        assert!(e.contains("missing required key 'M'"), "{e}");
        let e = "zirr-ref:J=auto"
            .parse::<EstimatorSpec>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("J = 'auto'"), "{e}");
        let e = "mean:M=3".parse::<EstimatorSpec>().unwrap_err().to_string();
        assert!(e.contains("valid keys: (none)"), "{e}");
        let e = "clamp:c=abc"
            .parse::<EstimatorSpec>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("c = 'abc'"), "{e}");
        let e = "mon:M".parse::<EstimatorSpec>().unwrap_err().to_string();
        assert!(e.contains("not key=value"), "{e}");
    }
}

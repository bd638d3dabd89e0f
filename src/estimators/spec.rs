//! Spec strings `name[:key=value,...]` (docs/estimators.md §1a) and their structured form.
//!
//! Parsing is strict: unknown names and keys list the valid ones, a repeated key or a missing
//! required key is an error, and integer keys take integer literals only. Printing gives the
//! canonical form (every key in table order, floats in shortest round-trip form), and parsing
//! the printed form gives the same spec back.

use super::{Clamp, Estimator, GiniDiagnostic, Gmon, GmonB, Jung, Mean, Mon, Zirr, ZirrRef};
use crate::error::{Error, Result};
use std::fmt;
use std::str::FromStr;

/// How many buffers Zirr's cascade has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CascadeSize {
    /// Grow on demand so no sample lies above the top buffer (docs/estimators.md §5, default for `zirr`).
    Auto,
    /// The paper's literal fixed cascade of J buffers.
    Fixed(usize),
}

/// Parameters shared by `zirr` and `zirr-ref` (docs/estimators.md §5, §5a).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZirrParams {
    /// Cascade base `b > 1`.
    pub b: f64,
    /// Number of buffers.
    pub j: CascadeSize,
    /// Robustness `kappa > 0`.
    pub kappa: f64,
    /// Lone-firefly count threshold `kappa_min >= 0`.
    pub kappa_min: f64,
    /// Luminance unit `u > 0`: buffer j's reference brightness is `u * b^j`.
    pub u: f64,
}

impl ZirrParams {
    /// The paper method's defaults: `b = 8, J = auto, kappa = 1, kappa_min = 1, u = 1`.
    pub const PAPER: ZirrParams = ZirrParams {
        b: 8.0,
        j: CascadeSize::Auto,
        kappa: 1.0,
        kappa_min: 1.0,
        u: 1.0,
    };
    /// The released code's defaults: as [`ZirrParams::PAPER`] but `J = 6`.
    pub const REFERENCE: ZirrParams = ZirrParams {
        j: CascadeSize::Fixed(6),
        ..ZirrParams::PAPER
    };
}

/// The structured form of a spec string: which estimator, with every parameter explicit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EstimatorSpec {
    /// `mean`
    Mean,
    /// `clamp:c=`
    Clamp {
        /// Clamping threshold.
        c: f64,
    },
    /// `mon:M=`
    Mon {
        /// Number of sets.
        m: usize,
    },
    /// `gini:M=` (the estimate is the Gini coefficient, a diagnostic)
    Gini {
        /// Number of sets.
        m: usize,
    },
    /// `gmonb:M=,threshold=`
    GmonB {
        /// Number of sets.
        m: usize,
        /// Gini threshold above which MoN replaces the mean.
        threshold: f64,
    },
    /// `gmon:M=`
    Gmon {
        /// Number of sets.
        m: usize,
    },
    /// `jung:sigma_image=,m_max=`
    Jung {
        /// Standard deviation of the image's samples.
        sigma_image: f64,
        /// Largest M (odd).
        m_max: usize,
    },
    /// `zirr:b=,J=,kappa=,kappa_min=,u=`
    Zirr(ZirrParams),
    /// `zirr-ref:b=,J=,kappa=,kappa_min=,u=`
    ZirrRef(ZirrParams),
    /// `pajot-rot:learn=`
    PajotRot {
        /// Learning-phase length.
        learn: usize,
    },
    /// `pajot-adr:learn=`
    PajotAdr {
        /// Learning-phase length.
        learn: usize,
    },
    /// `pajot-hybrid:learn=,T=,delta=`
    PajotHybrid {
        /// Learning-phase length.
        learn: usize,
        /// Successive agreeing updates before switching to ROT.
        t: usize,
        /// Relative agreement tolerance.
        delta: f64,
    },
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

/// Every estimator name with its keys in canonical order.
const TABLE: &[(&str, &[&str])] = &[
    ("mean", &[]),
    ("clamp", &["c"]),
    ("mon", &["M"]),
    ("gini", &["M"]),
    ("gmonb", &["M", "threshold"]),
    ("gmon", &["M"]),
    ("jung", &["sigma_image", "m_max"]),
    ("zirr", &["b", "J", "kappa", "kappa_min", "u"]),
    ("zirr-ref", &["b", "J", "kappa", "kappa_min", "u"]),
    ("pajot-rot", &["learn"]),
    ("pajot-adr", &["learn"]),
    ("pajot-hybrid", &["learn", "T", "delta"]),
];

impl EstimatorSpec {
    /// Every valid estimator name, in the spec table's order.
    pub fn names() -> impl Iterator<Item = &'static str> {
        TABLE.iter().map(|(n, _)| *n)
    }

    /// The estimator's name as written in spec strings.
    pub fn name(&self) -> &'static str {
        match self {
            EstimatorSpec::Mean => "mean",
            EstimatorSpec::Clamp { .. } => "clamp",
            EstimatorSpec::Mon { .. } => "mon",
            EstimatorSpec::Gini { .. } => "gini",
            EstimatorSpec::GmonB { .. } => "gmonb",
            EstimatorSpec::Gmon { .. } => "gmon",
            EstimatorSpec::Jung { .. } => "jung",
            EstimatorSpec::Zirr(_) => "zirr",
            EstimatorSpec::ZirrRef(_) => "zirr-ref",
            EstimatorSpec::PajotRot { .. } => "pajot-rot",
            EstimatorSpec::PajotAdr { .. } => "pajot-adr",
            EstimatorSpec::PajotHybrid { .. } => "pajot-hybrid",
        }
    }

    /// Whether the method's per-pixel memory is bounded independently of the stream
    /// (everything but Pajot's learning set and dubious list).
    pub fn is_constant_memory(&self) -> bool {
        !matches!(
            self,
            EstimatorSpec::PajotRot { .. }
                | EstimatorSpec::PajotAdr { .. }
                | EstimatorSpec::PajotHybrid { .. }
        )
    }

    /// Builds the estimator, checking every parameter.
    pub fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(match *self {
            EstimatorSpec::Mean => Box::new(Mean::new()),
            EstimatorSpec::Clamp { c } => Box::new(Clamp::new(c)?),
            EstimatorSpec::Mon { m } => Box::new(Mon::new(m)?),
            EstimatorSpec::Gini { m } => Box::new(GiniDiagnostic::new(m)?),
            EstimatorSpec::GmonB { m, threshold } => Box::new(GmonB::new(m, threshold)?),
            EstimatorSpec::Gmon { m } => Box::new(Gmon::new(m)?),
            EstimatorSpec::Jung { sigma_image, m_max } => Box::new(Jung::new(sigma_image, m_max)?),
            EstimatorSpec::Zirr(p) => Box::new(Zirr::new(p)?),
            EstimatorSpec::ZirrRef(p) => Box::new(ZirrRef::new(p)?),
            // PAJOT-ARMS: wired by the Pajot module.
            EstimatorSpec::PajotRot { learn } => Box::new(super::PajotRot::new(learn)?),
            EstimatorSpec::PajotAdr { learn } => Box::new(super::PajotAdr::new(learn)?),
            EstimatorSpec::PajotHybrid { learn, t, delta } => {
                Box::new(super::PajotHybrid::new(learn, t, delta)?)
            }
        })
    }
}

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

impl fmt::Display for EstimatorSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let zirr = |f: &mut fmt::Formatter<'_>, name: &str, p: &ZirrParams| {
            let j = match p.j {
                CascadeSize::Auto => "auto".to_string(),
                CascadeSize::Fixed(j) => j.to_string(),
            };
            write!(
                f,
                "{name}:b={},J={j},kappa={},kappa_min={},u={}",
                fmt_f64(p.b),
                fmt_f64(p.kappa),
                fmt_f64(p.kappa_min),
                fmt_f64(p.u)
            )
        };
        match self {
            EstimatorSpec::Mean => write!(f, "mean"),
            EstimatorSpec::Clamp { c } => write!(f, "clamp:c={}", fmt_f64(*c)),
            EstimatorSpec::Mon { m } => write!(f, "mon:M={m}"),
            EstimatorSpec::Gini { m } => write!(f, "gini:M={m}"),
            EstimatorSpec::GmonB { m, threshold } => {
                write!(f, "gmonb:M={m},threshold={}", fmt_f64(*threshold))
            }
            EstimatorSpec::Gmon { m } => write!(f, "gmon:M={m}"),
            EstimatorSpec::Jung { sigma_image, m_max } => {
                write!(
                    f,
                    "jung:sigma_image={},m_max={m_max}",
                    fmt_f64(*sigma_image)
                )
            }
            EstimatorSpec::Zirr(p) => zirr(f, "zirr", p),
            EstimatorSpec::ZirrRef(p) => zirr(f, "zirr-ref", p),
            EstimatorSpec::PajotRot { learn } => write!(f, "pajot-rot:learn={learn}"),
            EstimatorSpec::PajotAdr { learn } => write!(f, "pajot-adr:learn={learn}"),
            EstimatorSpec::PajotHybrid { learn, t, delta } => {
                write!(
                    f,
                    "pajot-hybrid:learn={learn},T={t},delta={}",
                    fmt_f64(*delta)
                )
            }
        }
    }
}

/// The key/value pairs of one spec string, consumed as they are read.
struct Keys<'a> {
    spec: &'a str,
    pairs: Vec<(&'a str, &'a str)>,
}

impl<'a> Keys<'a> {
    fn malformed(&self, reason: impl Into<String>) -> Error {
        Error::MalformedSpec {
            spec: self.spec.to_string(),
            reason: reason.into(),
        }
    }

    fn take(&mut self, key: &str) -> Option<&'a str> {
        let i = self.pairs.iter().position(|(k, _)| *k == key)?;
        Some(self.pairs.remove(i).1)
    }

    fn float(&mut self, key: &str, default: Option<f64>) -> Result<f64> {
        match self.take(key) {
            None => default.ok_or_else(|| self.malformed(format!("missing required key '{key}'"))),
            Some(v) => v
                .parse::<f64>()
                .map_err(|_| self.malformed(format!("{key} = '{v}' is not a number"))),
        }
    }

    fn int(&mut self, key: &str, default: Option<usize>) -> Result<usize> {
        match self.take(key) {
            None => default.ok_or_else(|| self.malformed(format!("missing required key '{key}'"))),
            Some(v) => parse_int(v)
                .ok_or_else(|| self.malformed(format!("{key} = '{v}' is not an integer literal"))),
        }
    }
}

/// A non-negative decimal integer literal (`5`, not `5.0` or `+5`).
fn parse_int(v: &str) -> Option<usize> {
    if v.is_empty() || !v.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    v.parse().ok()
}

impl FromStr for EstimatorSpec {
    type Err = Error;

    fn from_str(spec: &str) -> Result<Self> {
        let (name, rest) = match spec.split_once(':') {
            Some((n, r)) => (n.trim(), Some(r)),
            None => (spec.trim(), None),
        };
        let Some((_, valid_keys)) = TABLE.iter().find(|(n, _)| *n == name) else {
            return Err(Error::UnknownEstimator {
                name: name.to_string(),
                valid: EstimatorSpec::names().collect::<Vec<_>>().join(", "),
            });
        };
        let mut keys = Keys {
            spec,
            pairs: Vec::new(),
        };
        for item in rest.into_iter().flat_map(|r| r.split(',')) {
            let Some((k, v)) = item.split_once('=') else {
                return Err(keys.malformed(format!("'{item}' is not key=value")));
            };
            let (k, v) = (k.trim(), v.trim());
            if !valid_keys.contains(&k) {
                let valid = if valid_keys.is_empty() {
                    "(none)".to_string()
                } else {
                    valid_keys.join(", ")
                };
                return Err(Error::UnknownKey {
                    estimator: name.to_string(),
                    key: k.to_string(),
                    valid,
                });
            }
            if keys.pairs.iter().any(|(seen, _)| *seen == k) {
                return Err(keys.malformed(format!("key '{k}' given twice")));
            }
            keys.pairs.push((k, v));
        }
        let zirr = |keys: &mut Keys, defaults: ZirrParams, auto_ok: bool| -> Result<ZirrParams> {
            let j = match keys.take("J") {
                None => defaults.j,
                Some("auto") if auto_ok => CascadeSize::Auto,
                Some(v) => CascadeSize::Fixed(parse_int(v).ok_or_else(|| {
                    let expected = if auto_ok {
                        "an integer literal or 'auto'"
                    } else {
                        "an integer literal"
                    };
                    keys.malformed(format!("J = '{v}' is not {expected}"))
                })?),
            };
            Ok(ZirrParams {
                b: keys.float("b", Some(defaults.b))?,
                j,
                kappa: keys.float("kappa", Some(defaults.kappa))?,
                kappa_min: keys.float("kappa_min", Some(defaults.kappa_min))?,
                u: keys.float("u", Some(defaults.u))?,
            })
        };
        let k = &mut keys;
        Ok(match name {
            "mean" => EstimatorSpec::Mean,
            "clamp" => EstimatorSpec::Clamp {
                c: k.float("c", None)?,
            },
            "mon" => EstimatorSpec::Mon {
                m: k.int("M", None)?,
            },
            "gini" => EstimatorSpec::Gini {
                m: k.int("M", None)?,
            },
            "gmonb" => EstimatorSpec::GmonB {
                m: k.int("M", None)?,
                threshold: k.float("threshold", Some(0.25))?,
            },
            "gmon" => EstimatorSpec::Gmon {
                m: k.int("M", None)?,
            },
            "jung" => EstimatorSpec::Jung {
                sigma_image: k.float("sigma_image", None)?,
                m_max: k.int("m_max", Some(17))?,
            },
            "zirr" => EstimatorSpec::Zirr(zirr(k, ZirrParams::PAPER, true)?),
            "zirr-ref" => EstimatorSpec::ZirrRef(zirr(k, ZirrParams::REFERENCE, false)?),
            "pajot-rot" => EstimatorSpec::PajotRot {
                learn: k.int("learn", Some(50))?,
            },
            "pajot-adr" => EstimatorSpec::PajotAdr {
                learn: k.int("learn", Some(50))?,
            },
            "pajot-hybrid" => EstimatorSpec::PajotHybrid {
                learn: k.int("learn", Some(50))?,
                t: k.int("T", Some(2))?,
                delta: k.float("delta", Some(0.0))?,
            },
            _ => unreachable!("name checked against TABLE above"),
        })
    }
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

//! Serde-friendly descriptions of generators, so experiment files can name a preset or spell
//! out parameters, and reports can record exactly what was sampled.
//!
//! In TOML:
//!
//! ```toml
//! dist = { kind = "preset", name = "caustic" }
//! # or
//! dist = { kind = "pareto", scale = 1.0, shape = 1.5 }
//! # or
//! [dist]
//! kind = "mixture"
//! components = [
//!     { weight = 0.9, dist = { kind = "point-mass", value = 0.0 } },
//!     { weight = 0.1, dist = { kind = "lognormal", mu = 2.0, sigma = 0.5 } },
//! ]
//! ```

use serde::{Deserialize, Serialize};

use super::{Dist, LogNormal, Mixture, Pareto, PointMass, TruncatedPareto, preset};
use crate::error::{Error, Result};

/// Parameters of a generator, checked only when [built](DistSpec::build). A [`Dist`]
/// (de)serialises through this type, so deserialising a `Dist` runs the checked constructors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DistSpec {
    /// [`Pareto`]`(scale, shape)`.
    Pareto {
        /// Lower end of the support.
        scale: f64,
        /// Tail index, > 1.
        shape: f64,
    },
    /// [`TruncatedPareto`]`(scale, shape, upper)`.
    TruncatedPareto {
        /// Lower end of the support.
        scale: f64,
        /// Tail index, > 0.
        shape: f64,
        /// Upper end of the support.
        upper: f64,
    },
    /// [`LogNormal`]`(mu, sigma)`.
    #[serde(rename = "lognormal")]
    LogNormal {
        /// Location of `ln S`.
        mu: f64,
        /// Spread of `ln S`.
        sigma: f64,
    },
    /// [`PointMass`]`(value)`.
    PointMass {
        /// The value every draw takes.
        value: f64,
    },
    /// [`Mixture`] of weighted components (weights normalised).
    Mixture {
        /// The components, in order; errors name their index.
        components: Vec<ComponentSpec>,
    },
    /// A named preset, see [`super::Preset`].
    Preset {
        /// Preset name such as `caustic`.
        name: String,
    },
}

/// One weighted component of a [`DistSpec::Mixture`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComponentSpec {
    /// Relative weight (normalised over the mixture).
    pub weight: f64,
    /// The component's law.
    pub dist: DistSpec,
}

impl DistSpec {
    /// Runs the checked constructors. A component that fails inside a mixture — for example an
    /// untruncated Pareto with shape <= 1 — is reported as [`Error::Component`] with its index
    /// and the inner message (which names the parameter and value).
    pub fn build(&self) -> Result<Dist> {
        Ok(match self {
            DistSpec::Pareto { scale, shape } => Pareto::new(*scale, *shape)?.into(),
            DistSpec::TruncatedPareto {
                scale,
                shape,
                upper,
            } => TruncatedPareto::new(*scale, *shape, *upper)?.into(),
            DistSpec::LogNormal { mu, sigma } => LogNormal::new(*mu, *sigma)?.into(),
            DistSpec::PointMass { value } => PointMass::new(*value)?.into(),
            DistSpec::Mixture { components } => {
                let built = components
                    .iter()
                    .enumerate()
                    .map(|(i, c)| {
                        c.dist
                            .build()
                            .map(|d| (c.weight, d))
                            .map_err(|e| Error::Component {
                                component: i,
                                reason: e.to_string(),
                            })
                    })
                    .collect::<Result<Vec<_>>>()?;
                Mixture::new(built)?.into()
            }
            DistSpec::Preset { name } => preset(name)?,
        })
    }
}

impl From<&Dist> for DistSpec {
    fn from(d: &Dist) -> Self {
        match d {
            Dist::Pareto(p) => DistSpec::Pareto {
                scale: p.scale(),
                shape: p.shape(),
            },
            Dist::TruncatedPareto(p) => DistSpec::TruncatedPareto {
                scale: p.scale(),
                shape: p.shape(),
                upper: p.upper(),
            },
            Dist::LogNormal(l) => DistSpec::LogNormal {
                mu: l.mu(),
                sigma: l.sigma(),
            },
            Dist::PointMass(p) => DistSpec::PointMass { value: p.value() },
            Dist::Mixture(m) => DistSpec::Mixture {
                components: m
                    .weights()
                    .iter()
                    .zip(m.components())
                    .map(|(&weight, d)| ComponentSpec {
                        weight,
                        dist: d.into(),
                    })
                    .collect(),
            },
        }
    }
}

impl From<Dist> for DistSpec {
    fn from(d: Dist) -> Self {
        (&d).into()
    }
}

impl TryFrom<DistSpec> for Dist {
    type Error = Error;

    fn try_from(spec: DistSpec) -> Result<Self> {
        spec.build()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trip_and_validation() {
        let text = r#"{"kind":"mixture","components":[
            {"weight":0.9,"dist":{"kind":"point-mass","value":0.0}},
            {"weight":0.1,"dist":{"kind":"lognormal","mu":2.0,"sigma":0.5}}]}"#;
        let d: Dist = serde_json::from_str(text).unwrap();
        assert_eq!(
            d.to_string(),
            "mixture(0.9*point(value=0) + 0.1*lognormal(mu=2,sigma=0.5))"
        );
        let back: Dist = serde_json::from_str(&serde_json::to_string(&d).unwrap()).unwrap();
        assert_eq!(back, d);
        let preset: Dist = serde_json::from_str(r#"{"kind":"preset","name":"caustic"}"#).unwrap();
        assert_eq!(preset, super::super::Preset::Caustic.dist());
        // Checked constructors run on deserialisation.
        let bad = serde_json::from_str::<Dist>(r#"{"kind":"pareto","scale":1,"shape":0.9}"#);
        let msg = bad.unwrap_err().to_string();
        assert!(msg.contains("shape") && msg.contains("0.9"), "{msg}");
        // Typos in keys are errors, not silently ignored.
        assert!(
            serde_json::from_str::<DistSpec>(r#"{"kind":"pareto","scale":1,"shap":2}"#).is_err()
        );
    }

    #[test]
    fn toml_forms_parse() {
        #[derive(Deserialize)]
        struct Experiment {
            dist: Dist,
        }
        let e: Experiment =
            toml::from_str(r#"dist = { kind = "preset", name = "firefly" }"#).unwrap();
        assert_eq!(e.dist, super::super::Preset::Firefly.dist());
        let e: Experiment =
            toml::from_str(r#"dist = { kind = "pareto", scale = 1, shape = 1.5 }"#).unwrap();
        assert_eq!(e.dist.to_string(), "pareto(scale=1,shape=1.5)");
        let text = r#"
            [dist]
            kind = "mixture"
            components = [
                { weight = 0.9, dist = { kind = "point-mass", value = 0.0 } },
                { weight = 0.1, dist = { kind = "truncated-pareto", scale = 1.0, shape = 0.8, upper = 1e3 } },
            ]
        "#;
        let e: Experiment = toml::from_str(text).unwrap();
        assert_eq!(
            e.dist.to_string(),
            "mixture(0.9*point(value=0) + 0.1*truncated-pareto(scale=1,shape=0.8,upper=1000))"
        );
        let bad = toml::from_str::<Experiment>(r#"dist = { kind = "preset", name = "fire" }"#);
        let msg = bad.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(msg.contains("fire") && msg.contains("firefly"), "{msg}");
    }
}

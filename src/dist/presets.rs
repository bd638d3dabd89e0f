//! Named generators that mimic the luminance of one path-traced pixel.
//!
//! Measured per-pixel streams of real scenes show two different heavy tails, and the presets
//! cover both: a *spike* (caustic pixels: rare hits of one fixed large value, the light's
//! radiance times the albedo) and a *power law* (pixels lit through a mirror: a bounded Pareto
//! tail). Every preset is scaled to mean 1, so a bias reads directly as a relative bias;
//! [`Dist::mean`] reports the exact mean of the parameters as stored, which is 1 to within a
//! few ulps where a parameter is derived to hit it.
//!
//! Laws are written `lognormal(mu, sigma)`, `pareto(scale, shape)`,
//! `truncated-pareto(scale, shape, upper)` and `point(value)`; derived values to 6 digits:
//!
//! | preset              | law                                                         | variance |
//! |---------------------|-------------------------------------------------------------|----------|
//! | `diffuse`           | lognormal(-0.125, 0.5)                                      | 0.284025 |
//! | `glossy`            | lognormal(-1.125, 1.5)                                      | 8.48774  |
//! | `caustic`           | 0.45 point(0) + 0.54955 lognormal(-1.98518, 0.75)           | 1799.03  |
//! |                     | + 0.00045 point(2000)                                       |          |
//! | `mirror-lit`        | 0.99 point(0) + 0.01 truncated-pareto(19.8053, 1.2, 198053) | 9318.41  |
//! | `firefly`           | 0.99999 lognormal(-0.616524, 1) + 0.00001 pareto(1000, 1.1) | infinite |
//! | `black-speckle`     | 0.9 point(0) + 0.1 lognormal(2.17759, 0.5)                  | 11.8403  |
//! | `infinite-variance` | pareto(1/3, 1.5)                                            | infinite |

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{Dist, LogNormal, Mixture, Pareto, PointMass, TruncatedPareto};
use crate::error::{Error, Result};

/// A named pixel-luminance generator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// A directly lit diffuse surface: every path carries a similar amount of light.
    /// `lognormal(mu = -0.125, sigma = 0.5)`, mean 1, variance `e^0.25 - 1 = 0.284025`.
    Diffuse,
    /// A rough glossy reflection of an extended light: contributions spread over orders of
    /// magnitude but no fireflies. `lognormal(mu = -1.125, sigma = 1.5)`, mean 1, variance
    /// `e^2.25 - 1 = 8.48774`.
    Glossy,
    /// A diffuse surface under a caustic: 45% of paths are black, an ordinary lognormal body
    /// carries 10% of the mean, and with probability 4.5e-4 a path hits the light and returns
    /// the one fixed value 2000 (radiance x albedo, 2000x the pixel mean), which carries the
    /// other 90%. `0.45 point(0) + 0.54955 lognormal(mu = ln(0.1 / 0.54955) - 0.28125 =
    /// -1.98518, sigma = 0.75) + 0.00045 point(2000)`, mean 1, variance 1799.03.
    Caustic,
    /// A pixel lit only through a mirror: 99% of paths find nothing, the rest follow a genuine
    /// power law (Hill shape 1.2) cut off at the light's maximum, 10^4 times the smallest hit.
    /// `0.99 point(0) + 0.01 truncated-pareto(scale = 19.8053, shape = 1.2, upper = 198053)`
    /// with the scale solved for mean 1; variance 9318.41.
    MirrorLit,
    /// An ordinary pixel with rare, extreme fireflies: a lognormal body and a 1e-5 Pareto tail
    /// of shape 1.1 starting at 1000 that carries 11% of the mean. `0.99999 lognormal(mu =
    /// ln(0.89 / 0.99999) - 0.5 = -0.616524, sigma = 1) + 0.00001 pareto(scale = 1000,
    /// shape = 1.1)`, mean 1, variance infinite.
    Firefly,
    /// A mostly occluded pixel (shadow edge, foliage): 90% black, the rest a lognormal of mean
    /// 10. `0.9 point(0) + 0.1 lognormal(mu = ln 10 - 0.125 = 2.17759, sigma = 0.5)`, mean 1,
    /// variance 11.8403.
    BlackSpeckle,
    /// The textbook case where the mean converges but the central limit theorem does not:
    /// `pareto(scale = 1/3, shape = 1.5)`, mean 1, variance infinite.
    InfiniteVariance,
}

impl Preset {
    /// Every preset, in documentation order.
    pub const ALL: [Preset; 7] = [
        Preset::Diffuse,
        Preset::Glossy,
        Preset::Caustic,
        Preset::MirrorLit,
        Preset::Firefly,
        Preset::BlackSpeckle,
        Preset::InfiniteVariance,
    ];

    /// The name used in experiment files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Diffuse => "diffuse",
            Preset::Glossy => "glossy",
            Preset::Caustic => "caustic",
            Preset::MirrorLit => "mirror-lit",
            Preset::Firefly => "firefly",
            Preset::BlackSpeckle => "black-speckle",
            Preset::InfiniteVariance => "infinite-variance",
        }
    }

    /// The generator. The parameters are constants checked by the unit tests, so this cannot
    /// fail.
    pub fn dist(self) -> Dist {
        self.build()
            .expect("preset parameters are valid constants (checked by unit tests)")
    }

    fn build(self) -> Result<Dist> {
        let zero = || Dist::from(PointMass::ZERO);
        Ok(match self {
            Preset::Diffuse => LogNormal::new(-0.125, 0.5)?.into(),
            Preset::Glossy => LogNormal::new(-1.125, 1.5)?.into(),
            Preset::Caustic => {
                // The three weights sum to 1 within rounding, so they are stored as written.
                let (w_zero, w_body, w_spike, spike): (f64, f64, f64, f64) =
                    (0.45, 0.54955, 0.00045, 2000.0);
                let sigma = 0.75;
                let body_mean = (1.0 - w_spike * spike) / w_body;
                let mu = body_mean.ln() - 0.5 * sigma * sigma;
                Mixture::new(vec![
                    (w_zero, zero()),
                    (w_body, LogNormal::new(mu, sigma)?.into()),
                    (w_spike, PointMass::new(spike)?.into()),
                ])?
                .into()
            }
            Preset::MirrorLit => {
                let (w_hit, shape, range) = (0.01, 1.2, 1e4);
                // Mean of the tail law with unit scale, then the scale that makes the mean 1.
                let unit_mean = TruncatedPareto::new(1.0, shape, range)?.mean();
                let scale = 1.0 / (w_hit * unit_mean);
                Mixture::new(vec![
                    (1.0 - w_hit, zero()),
                    (
                        w_hit,
                        TruncatedPareto::new(scale, shape, range * scale)?.into(),
                    ),
                ])?
                .into()
            }
            Preset::Firefly => {
                let tail = Pareto::new(1000.0, 1.1)?;
                let w_tail = 1e-5;
                let w_body = 1.0 - w_tail;
                let sigma = 1.0;
                let body_mean = (1.0 - w_tail * tail.mean()) / w_body;
                let mu = body_mean.ln() - 0.5 * sigma * sigma;
                Mixture::new(vec![
                    (w_body, LogNormal::new(mu, sigma)?.into()),
                    (w_tail, tail.into()),
                ])?
                .into()
            }
            Preset::BlackSpeckle => Mixture::new(vec![
                (0.9, zero()),
                (0.1, LogNormal::new(10f64.ln() - 0.125, 0.5)?.into()),
            ])?
            .into(),
            Preset::InfiniteVariance => Pareto::new(1.0 / 3.0, 1.5)?.into(),
        })
    }

    /// Comma-separated list of valid names, for error messages.
    fn valid_names() -> String {
        Preset::ALL.map(Preset::name).join(", ")
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = Error;

    /// An unknown name is an error listing the valid ones.
    fn from_str(name: &str) -> Result<Self> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| {
                Error::param(
                    "preset",
                    format!("'{name}'"),
                    format!("unknown preset; valid presets: {}", Preset::valid_names()),
                )
            })
    }
}

/// The generator of the preset called `name`; an unknown name is an error listing valid ones.
pub fn preset(name: &str) -> Result<Dist> {
    Ok(name.parse::<Preset>()?.dist())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_builds_with_mean_one() {
        for p in Preset::ALL {
            let d = p.build().unwrap_or_else(|e| panic!("{p}: {e}"));
            assert!((d.mean() - 1.0).abs() < 1e-14, "{p}: mean {}", d.mean());
            assert_eq!(p.name().parse::<Preset>().unwrap(), p);
        }
    }

    #[test]
    fn documented_variances_and_parameters() {
        let var = |p: Preset| p.dist().variance();
        let close = |a: f64, b: f64| ((a - b) / b).abs() < 5e-6;
        assert!(close(var(Preset::Diffuse).unwrap(), 0.284025));
        assert!(close(var(Preset::Glossy).unwrap(), 8.48774));
        assert!(close(var(Preset::Caustic).unwrap(), 1799.03));
        assert!(close(var(Preset::MirrorLit).unwrap(), 9318.41));
        assert!(close(var(Preset::BlackSpeckle).unwrap(), 11.8403));
        assert_eq!(var(Preset::Firefly), None);
        assert_eq!(var(Preset::InfiniteVariance), None);
        let Dist::Mixture(m) = Preset::MirrorLit.dist() else {
            panic!()
        };
        let Dist::TruncatedPareto(tp) = m.components()[1] else {
            panic!()
        };
        assert!(close(tp.scale(), 19.8053) && close(tp.upper(), 198053.0));
        // The caustic spike is 2000x the pixel mean.
        let Dist::Mixture(m) = Preset::Caustic.dist() else {
            panic!()
        };
        let Dist::LogNormal(body) = m.components()[1] else {
            panic!()
        };
        assert!(
            close(body.mu(), -1.98518)
                && m.components()[2] == Dist::from(PointMass::new(2000.0).unwrap())
        );
        let Dist::Mixture(m) = Preset::Firefly.dist() else {
            panic!()
        };
        let Dist::LogNormal(body) = m.components()[0] else {
            panic!()
        };
        assert!(close(body.mu(), -0.616524));
    }

    #[test]
    fn unknown_preset_lists_valid_names() {
        let e = preset("causticc").unwrap_err().to_string();
        assert!(
            e.contains("causticc") && e.contains("mirror-lit") && e.contains("infinite-variance"),
            "{e}"
        );
    }
}

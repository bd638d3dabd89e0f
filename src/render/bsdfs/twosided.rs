//! Mitsuba's `twosided`: the nested one-sided BSDF mirrored onto the back side by flipping `z`.

use super::{Bsdf, BsdfSample, SurfacePoint, flip_z};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// The nested BSDF seen from the front on both sides.
#[derive(Debug, Clone)]
pub struct TwoSided(pub Arc<dyn Bsdf>);

/// The message for a BSDF that `twosided` may not wrap.
const REFUSED: &str = "twosided cannot wrap a twosided bsdf or one that transmits light \
                       (dielectric, mask, ...)";

/// Reads `<bsdf type="twosided">` with exactly one nested BSDF.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let inner = p.objects(&["bsdf", "ref"]);
    p.finish()?;
    let inner = match inner.as_slice() {
        [] => return Err(p.err(None, "twosided needs one nested <bsdf>")),
        [inner] => *inner,
        [_, second, ..] => {
            return Err(p.err(
                Some(*second),
                "a second bsdf in twosided: different front and back BSDFs are not supported",
            ));
        }
    };
    let ld = p.loader();
    // Checked before reading the inner bsdf: reading it first let a file of twosided nested a
    // million deep recurse until the stack overflowed.
    if inner.tag_name().name() == "bsdf"
        && matches!(ld.attr(inner, "type")?.as_deref(), Some("twosided"))
    {
        return Err(p.err(Some(inner), REFUSED));
    }
    let nested = ld.nested_bsdf(inner)?;
    if nested.is_twosided() || nested.transmits() {
        return Err(p.err(Some(inner), REFUSED));
    }
    Ok(Arc::new(TwoSided(nested)))
}

impl Bsdf for TwoSided {
    fn has_smooth_lobe(&self) -> bool {
        self.0.has_smooth_lobe()
    }

    fn uses_uv(&self) -> bool {
        self.0.uses_uv()
    }

    fn reads_tangents(&self) -> bool {
        self.0.reads_tangents()
    }

    fn is_twosided(&self) -> bool {
        true
    }

    /// The nested albedo (the same on both sides).
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.0.albedo(at)
    }

    /// Seen from the back, the nested BSDF's normal for the mirrored viewer, mirrored back.
    fn feature_normal(&self, at: &SurfacePoint, wi: Vec3) -> Option<Vec3> {
        if wi.z < 0.0 {
            self.0.feature_normal(at, flip_z(wi)).map(flip_z)
        } else {
            self.0.feature_normal(at, wi)
        }
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        if wi.z < 0.0 {
            self.0.eval_pdf(at, flip_z(wi), flip_z(wo))
        } else {
            self.0.eval_pdf(at, wi, wo)
        }
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z < 0.0 {
            let mut s = self.0.sample(at, flip_z(wi), u_lobe, u)?;
            s.wo = flip_z(s.wo);
            Some(s)
        } else {
            self.0.sample(at, wi, u_lobe, u)
        }
    }
}

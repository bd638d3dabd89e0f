//! The sensor side of a scene: `path` integrator, `perspective` sensor, `hdrfilm` with its
//! reconstruction filter, `independent` sampler.

use glam::{Mat3, Vec3};
use roxmltree::Node;

use super::props::Params;
use super::{
    Loader, SIMILARITY_TOLERANCE, beyond_limit, beyond_message, list, num, value_or, vec_text,
};
use crate::error::Result;
use crate::limits::shorten;
use crate::render::scene::{CameraDesc, FovAxis, IntegratorDesc};

/// Mitsuba's `hdrfilm` pixel formats; accepted and ignored (they do not change pixel values).
pub(crate) const PIXEL_FORMATS: &[&str] =
    &["luminance", "luminance_alpha", "rgb", "rgba", "xyz", "xyza"];

/// Mitsuba's `hdrfilm` component formats; accepted and ignored.
/// Mitsuba's `hdrfilm` file formats; accepted and ignored.
pub(crate) const FILE_FORMATS: &[&str] = &["openexr", "exr", "rgbe", "hdr", "pfm"];

/// Mitsuba's reconstruction filters: `box` is modelled, the others only with the override.
pub(crate) const RFILTERS: &[&str] = &[
    "box",
    "tent",
    "gaussian",
    "mitchell",
    "catmullrom",
    "lanczos",
];

pub(crate) const COMPONENT_FORMATS: &[&str] = &["float16", "float32", "uint32"];

impl<'a, 'i> Loader<'a, 'i> {
    /// `<integrator type="path">`.
    pub(super) fn integrator(&mut self, node: Node<'a, 'i>) -> Result<IntegratorDesc> {
        self.check_attrs(node, &["type", "id"])?;
        self.register_id(node)?;
        self.plugin_type(node, "integrator", &["path"])?;
        let mut props = Params::collect(self, node)?;
        let max_depth = props.integer("max_depth")?;
        let rr_depth = props.integer("rr_depth")?;
        props.finish()?;

        let max_depth = match max_depth {
            None | Some((-1, _)) => None,
            Some((0, at)) => {
                return Err(self.err(
                    at,
                    "max_depth = 0 would render nothing, not even emitters; use -1 (unbounded) \
                     or a depth >= 1",
                ));
            }
            Some((depth, at)) => Some(u32::try_from(depth).map_err(|_| {
                self.err(
                    at,
                    format!("max_depth = {depth}: must be -1 (unbounded) or in 1..=4294967295"),
                )
            })?),
        };
        let rr_depth = match rr_depth {
            None => IntegratorDesc::default().rr_depth,
            Some((depth, at)) => {
                u32::try_from(depth)
                    .ok()
                    .filter(|d| *d >= 1)
                    .ok_or_else(|| {
                        self.err(at, format!("rr_depth = {depth}: must be in 1..=4294967295"))
                    })?
            }
        };
        Ok(IntegratorDesc {
            max_depth,
            rr_depth,
        })
    }

    /// `<sensor type="perspective">` with its film and sampler.
    pub(super) fn sensor(&mut self, node: Node<'a, 'i>) -> Result<CameraDesc> {
        self.check_attrs(node, &["type", "id"])?;
        self.register_id(node)?;
        self.plugin_type(node, "sensor", &["perspective"])?;
        let mut props = Params::collect(self, node)?;
        let films = props.objects(&["film"]);
        let samplers = props.objects(&["sampler"]);
        let fov = props.float("fov")?;
        let fov_axis = props.string("fov_axis")?;
        let to_world = props.transform("to_world")?;
        let near_clip = props.float("near_clip")?;
        let far_clip = props.float("far_clip")?;
        props.reject(
            "focal_length",
            "give the field of view as <float name=\"fov\"> instead",
        )?;
        props.finish()?;

        let Some((fov_deg, fov_at)) = fov else {
            return Err(self.err(node, "missing required parameter <float name=\"fov\">"));
        };
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(self.err(
                fov_at,
                format!("fov = {}: must be in (0, 180) degrees", num(fov_deg)),
            ));
        }
        let fov_axis = match fov_axis {
            None => FovAxis::X,
            Some((axis, at)) => match axis.as_str() {
                "x" => FovAxis::X,
                "y" => FovAxis::Y,
                "diagonal" => FovAxis::Diagonal,
                "smaller" => FovAxis::Smaller,
                "larger" => FovAxis::Larger,
                _ => {
                    return Err(self.err(
                        at,
                        format!(
                            "fov_axis = \"{}\": must be x, y, diagonal, smaller or larger",
                            shorten(&axis)
                        ),
                    ));
                }
            },
        };
        let to_world_at = to_world.map(|(_, at)| at);
        let to_world = self.affine(to_world)?;
        let origin = to_world.w_axis.truncate();
        if let Some(reach) = beyond_limit(origin) {
            let what = format!("the camera position {}", vec_text(origin));
            return Err(self.err(to_world_at.unwrap_or(node), beyond_message(&what, reach)));
        }
        if let Some(at) = to_world_at {
            let linear = Mat3::from_mat4(to_world);
            let lengths = Vec3::new(
                linear.x_axis.length(),
                linear.y_axis.length(),
                linear.z_axis.length(),
            );
            let dots = Vec3::new(
                linear.x_axis.dot(linear.y_axis),
                linear.y_axis.dot(linear.z_axis),
                linear.z_axis.dot(linear.x_axis),
            );
            if (lengths - Vec3::ONE).abs().max_element() > SIMILARITY_TOLERANCE
                || dots.abs().max_element() > SIMILARITY_TOLERANCE
            {
                return Err(self.err(
                    at,
                    format!(
                        "the camera transform scales or shears (axis lengths {}, \
                         pairwise dot products {}); Mitsuba forbids scale factors in a \
                         camera-to-world transform",
                        vec_text(lengths),
                        vec_text(dots)
                    ),
                ));
            }
        }
        let near = value_or(near_clip, 0.01);
        let far = value_or(far_clip, 10000.0);
        if !(near > 0.0) {
            let at = near_clip.map_or(node, |(_, at)| at);
            return Err(self.err(at, format!("near_clip = {}: must be > 0", num(near))));
        }
        if !(far > near) {
            let at = far_clip.or(near_clip).map_or(node, |(_, at)| at);
            return Err(self.err(
                at,
                format!(
                    "far_clip = {} must exceed near_clip = {}",
                    num(far),
                    num(near)
                ),
            ));
        }

        let (width, height, replaced_filter) = match films.as_slice() {
            // Mitsuba's default film: 768x576 with a gaussian filter.
            [] if self.box_override => (768, 576, Some("gaussian".to_string())),
            [] => {
                return Err(self.err(
                    node,
                    "missing <film type=\"hdrfilm\">: Mitsuba's default film reconstructs with \
                     a gaussian filter, which is not modelled; add an hdrfilm with \
                     <rfilter type=\"box\"/>, or pass --rfilter box",
                ));
            }
            [film] => self.film(*film)?,
            [_, second, ..] => {
                return Err(self.err(*second, "a sensor takes exactly one <film>"));
            }
        };
        let spp = match samplers.as_slice() {
            // Mitsuba's default sampler is `independent` with 4 samples per pixel.
            [] => 4,
            [sampler] => self.sampler(*sampler)?,
            [_, second, ..] => {
                return Err(self.err(*second, "a sensor takes at most one <sampler>"));
            }
        };
        Ok(CameraDesc {
            to_world,
            fov_deg,
            fov_axis,
            width,
            height,
            spp,
            replaced_filter,
            near_clip: near,
            far_clip: far,
        })
    }

    /// `<film type="hdrfilm">`; returns (width, height, the non-box filter the override
    /// replaced).
    ///
    /// `file_format`, `pixel_format`, `component_format`, `banner` and `high_quality_edges` are
    /// read and have no effect: they change how Mitsuba stores the image, not the pixel values
    /// the estimators see (`high_quality_edges` only matters for filters wider than a pixel,
    /// which the box filter is not).
    fn film(&self, node: Node<'a, 'i>) -> Result<(u32, u32, Option<String>)> {
        self.check_attrs(node, &["type", "name"])?;
        self.plugin_type(node, "film", &["hdrfilm"])?;
        let mut props = Params::collect(self, node)?;
        let filters = props.objects(&["rfilter"]);
        let width = props.integer("width")?;
        let height = props.integer("height")?;
        let pixel_format = props.string("pixel_format")?;
        let component_format = props.string("component_format")?;
        let file_format = props.string("file_format")?;
        props.boolean("banner")?;
        props.boolean("high_quality_edges")?;
        props.finish()?;

        let mut size = [768, 576];
        for (slot, given, name) in [(0, width, "width"), (1, height, "height")] {
            if let Some((value, at)) = given {
                size[slot] = u32::try_from(value)
                    .ok()
                    .filter(|v| *v >= 1)
                    .ok_or_else(|| {
                        self.err(at, format!("{name} = {value}: must be in 1..=4294967295"))
                    })?;
            }
        }
        for (given, allowed) in [
            (pixel_format, PIXEL_FORMATS),
            (component_format, COMPONENT_FORMATS),
            (file_format, FILE_FORMATS),
        ] {
            if let Some((value, at)) = given {
                if !allowed.contains(&value.as_str()) {
                    return Err(self.err(
                        at,
                        format!("\"{}\" is not one of {}", shorten(&value), list(allowed)),
                    ));
                }
            }
        }
        let requested = match filters.as_slice() {
            [] => "gaussian".to_string(),
            [filter] => {
                self.check_attrs(*filter, &["type", "name"])?;
                let ty = self.plugin_type(*filter, "rfilter", RFILTERS)?;
                let mut filter_props = Params::collect(self, *filter)?;
                if self.box_override {
                    // Replaced wholesale: its radius or stddev means nothing to a box.
                    filter_props.ignore_all();
                }
                filter_props.finish()?;
                ty
            }
            [_, second, ..] => return Err(self.err(*second, "a film takes exactly one <rfilter>")),
        };
        if requested == "box" {
            return Ok((size[0], size[1], None));
        }
        if self.box_override {
            return Ok((size[0], size[1], Some(requested)));
        }
        let at = filters.first().copied().unwrap_or(node);
        let what = if filters.is_empty() {
            "the film has no <rfilter>, so Mitsuba reconstructs with its default gaussian filter"
                .to_string()
        } else {
            format!("the film asks for the \"{requested}\" reconstruction filter")
        };
        Err(self.err(
            at,
            format!(
                "{what}; per-pixel estimators need every sample to belong to exactly one pixel (a \
                 box filter). Give <rfilter type=\"box\"/>, or pass --rfilter box to render \
                 with a box filter anyway (render.json records it; render a Mitsuba reference \
                 with a box filter too)"
            ),
        ))
    }

    /// `<sampler type="independent">`; returns its `sample_count`.
    fn sampler(&self, node: Node<'a, 'i>) -> Result<u32> {
        self.check_attrs(node, &["type", "name"])?;
        self.plugin_type(node, "sampler", &["independent"])?;
        let mut props = Params::collect(self, node)?;
        let count = props.integer("sample_count")?;
        // The seed only selects Mitsuba's random sequence; accepted and not used.
        props.integer("seed")?;
        props.finish()?;
        match count {
            None => Ok(4),
            Some((value, at)) => u32::try_from(value)
                .ok()
                .filter(|v| *v >= 1)
                .ok_or_else(|| {
                    self.err(
                        at,
                        format!("sample_count = {value}: must be in 1..=4294967295"),
                    )
                }),
        }
    }
}

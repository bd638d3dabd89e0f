//! Mitsuba's `perspective` sensor with a box-filtered film: a sample's position is uniform in
//! its pixel, so a pixel's value is the plain average of its samples (or what an estimator
//! makes of them).

use super::scene::{CameraDesc, FovAxis};
use super::shapes::Ray;
use glam::{Mat4, Vec2, Vec3};

/// A pinhole camera in world space.
#[derive(Debug, Clone)]
pub struct Camera {
    to_world: Mat4,
    origin: Vec3,
    /// Half-extents of the image plane at unit distance.
    tan_half: Vec2,
    width: u32,
    height: u32,
    near_clip: f32,
    far_clip: f32,
}

/// A camera ray and the interval of distances it may hit within (the clipping planes).
#[derive(Debug, Clone, Copy)]
pub struct CameraRay {
    /// The ray.
    pub ray: Ray,
    /// Nearest distance along the ray (near clipping plane).
    pub tmin: f32,
    /// Farthest distance along the ray (far clipping plane).
    pub tmax: f32,
}

impl Camera {
    /// The camera of a scene description.
    pub fn new(d: &CameraDesc) -> Self {
        let (w, h) = (d.width as f32, d.height as f32);
        let aspect = w / h;
        let t = (d.fov_deg.to_radians() / 2.0).tan();
        let axis = match d.fov_axis {
            FovAxis::Smaller if w <= h => FovAxis::X,
            FovAxis::Smaller => FovAxis::Y,
            FovAxis::Larger if w >= h => FovAxis::X,
            FovAxis::Larger => FovAxis::Y,
            a => a,
        };
        let tan_half = match axis {
            FovAxis::X => Vec2::new(t, t / aspect),
            FovAxis::Y => Vec2::new(t * aspect, t),
            _ => {
                let diag = (w * w + h * h).sqrt();
                Vec2::new(t * w / diag, t * h / diag)
            }
        };
        Camera {
            to_world: d.to_world,
            origin: d.to_world.transform_point3(Vec3::ZERO),
            tan_half,
            width: d.width,
            height: d.height,
            near_clip: d.near_clip,
            far_clip: d.far_clip,
        }
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The ray through pixel `(x, y)` (row 0 at the top) at offset `u ∈ [0,1)²` inside it.
    /// Image left is the camera's local `+x`, image top its local `+y` (Mitsuba's convention).
    #[inline]
    pub fn ray(&self, x: u32, y: u32, u: Vec2) -> CameraRay {
        let fx = (x as f32 + u.x) / self.width as f32;
        let fy = (y as f32 + u.y) / self.height as f32;
        let local = Vec3::new(
            (1.0 - 2.0 * fx) * self.tan_half.x,
            (1.0 - 2.0 * fy) * self.tan_half.y,
            1.0,
        );
        let d = self.to_world.transform_vector3(local).normalize();
        // The clipping planes are perpendicular to the view axis: distance along the ray
        // scales with 1/cos of the angle to it, which is 1/|local| on the unit-z plane.
        let cos = local.length_recip();
        CameraRay {
            ray: Ray { o: self.origin, d },
            tmin: self.near_clip / cos,
            tmax: self.far_clip / cos,
        }
    }
}

//! Camera rays: a pinhole camera with a vertical field of view, through pixel centres.

use glam::Vec3;

use crate::geometry::Ray;
use crate::scene::Camera;

/// A camera prepared for generating rays.
#[derive(Clone, Copy, Debug)]
pub struct RayGenerator {
    origin: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    half_w: f32,
    half_h: f32,
    width: u32,
    height: u32,
}

impl RayGenerator {
    /// Prepares `cam`. Image x grows along `up x forward` ("right" when looking along +z
    /// with +y up, a left-handed view as in the source reports), image y grows downwards.
    pub fn new(cam: &Camera) -> Self {
        let forward = cam.forward.normalize();
        let right = cam.up.cross(forward).normalize();
        let up = forward.cross(right);
        let half_h = (cam.fov_y_deg.to_radians() * 0.5).tan();
        let half_w = half_h * cam.width as f32 / cam.height as f32;
        RayGenerator {
            origin: cam.position,
            forward,
            right,
            up,
            half_w,
            half_h,
            width: cam.width,
            height: cam.height,
        }
    }

    /// The unit-direction ray through the centre of pixel (`x`, `y`).
    #[inline]
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        let u = (2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0) * self.half_w;
        let v = (1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32) * self.half_h;
        Ray::new(self.origin, (self.forward + self.right * u + self.up * v).normalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_forward_and_right_is_plus_x() {
        let cam = Camera { width: 101, height: 101, ..Camera::default() };
        let g = RayGenerator::new(&cam);
        assert!((g.ray(50, 50).dir - Vec3::Z).length() < 1e-6);
        assert!(g.ray(100, 50).dir.x > 0.0);
        assert!(g.ray(50, 0).dir.y > 0.0);
        // A 1x1 viewport at distance 1: the edge pixel centre is just inside x = 0.5.
        let d = g.ray(100, 50).dir;
        assert!((d.x / d.z - 0.5 * 100.0 / 101.0).abs() < 1e-5);
    }
}

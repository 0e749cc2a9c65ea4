//! Camera rays: a pinhole camera with a vertical field of view, through pixel centres.

use glam::Vec3;

use crate::base::Ray;
use crate::scene::Camera;

/// A camera prepared for generating rays.
#[derive(Clone, Copy, Debug)]
pub struct RayGenerator {
    /// Eye position.
    pub origin: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit image x direction (`up x forward`).
    pub right: Vec3,
    /// Unit image up direction (image y grows downwards).
    pub up: Vec3,
    /// Half the image plane's width at unit distance.
    pub half_w: f32,
    /// Half the image plane's height at unit distance.
    pub half_h: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
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

    /// The unit-direction ray through the centre of pixel (`x`, `y`): [`Self::ray_uv`] at
    /// ([`Self::u`]`(x)`, [`Self::v`]`(y)`).
    #[inline]
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        self.ray_uv(self.u(x), self.v(y))
    }

    /// The horizontal image-plane coordinate of pixel column `x`'s centre (`-half_w` at
    /// the left edge, `half_w` at the right, at unit distance along `forward`).
    #[inline]
    pub fn u(&self, x: u32) -> f32 {
        (2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0) * self.half_w
    }

    /// The vertical image-plane coordinate of pixel row `y`'s centre (`half_h` at the top).
    #[inline]
    pub fn v(&self, y: u32) -> f32 {
        (1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32) * self.half_h
    }

    /// The length of the (unnormalised) direction `forward + right u + up v` through pixel
    /// (`x`, `y`)'s centre: a view depth times it is the distance along the unit ray (the
    /// rasterizer's depth to the tracer's `t`).
    pub fn depth_to_distance(&self, x: u32, y: u32) -> f32 {
        let (u, v) = (self.u(x), self.v(y));
        (1.0 + u * u + v * v).sqrt()
    }

    /// The unit-direction ray through image-plane point (`u`, `v`).
    #[inline]
    pub fn ray_uv(&self, u: f32, v: f32) -> Ray {
        Ray::new(self.origin, (self.forward + self.right * u + self.up * v).normalize())
    }

    /// [`Self::ray_uv`] at eight image-plane points at once, bit for bit (the same single
    /// precision operations in the same order, lane by lane; plain Rust that the compiler
    /// may vectorise, with no intrinsics of its own).
    #[inline]
    pub fn rays_uv8(&self, u: &[f32; 8], v: &[f32; 8]) -> [Ray; 8] {
        std::array::from_fn(|i| self.ray_uv(u[i], v[i]))
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

    #[test]
    fn eight_rays_at_once_equal_one_by_one() {
        let cam = Camera {
            width: 97,
            height: 61,
            forward: Vec3::new(0.3, -0.2, 1.0),
            up: Vec3::new(0.1, 1.0, 0.0),
            ..Camera::default()
        };
        let g = RayGenerator::new(&cam);
        for y0 in (0..61).step_by(7) {
            for x0 in (0..97).step_by(5) {
                let px: [(u32, u32); 8] =
                    std::array::from_fn(|i| ((x0 + 3 * i as u32) % 97, (y0 + i as u32) % 61));
                let rays = g.rays_uv8(&px.map(|(x, _)| g.u(x)), &px.map(|(_, y)| g.v(y)));
                for (r, (x, y)) in rays.iter().zip(px) {
                    let one = g.ray(x, y);
                    assert_eq!(r.origin, one.origin);
                    assert_eq!(
                        r.dir.to_array().map(f32::to_bits),
                        one.dir.to_array().map(f32::to_bits),
                        "({x}, {y})"
                    );
                }
            }
        }
    }
}

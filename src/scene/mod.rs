//! A scene as the tracer uses it: camera, render settings, lights, materials and the
//! object trees. Built from a TOML scene file by [`file`], or from any input file (scene,
//! mesh or grid) by [`load_input`]; independent of the representation each object is
//! rendered with.

pub mod camera;
pub mod file;
pub mod input;
pub mod shape;

pub use crate::base::transform;

use glam::Vec3;

use crate::scene::shape::{MeshLayout, Object};

pub use file::{load_scene, parse_scene};
pub use input::{grid_preview_scene, implicit_preview_scene, load_input, mesh_preview_scene, preparation};

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position, scene units.
    pub position: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Up hint (not parallel to `forward`), unit length.
    pub up: Vec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub fov_y_deg: f32,
    /// Image width, pixels, >= 1.
    pub width: u32,
    /// Image height, pixels, >= 1.
    pub height: u32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            position: Vec3::ZERO,
            forward: Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: 2.0 * 0.5f32.atan().to_degrees(),
            width: 500,
            height: 500,
        }
    }
}

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Maximum recursion depth for reflection and refraction (0 = local shading only).
    pub max_depth: u32,
    /// Colour of rays that hit nothing, linear RGB in [0, 1].
    pub background: Vec3,
    /// Rays are traced up to this distance, scene units.
    pub max_distance: f32,
    /// How loaded meshes (mesh files and scene `mesh` objects) store their BVH when traced
    /// as triangles: not in the scene file, set by `--layout`.
    pub mesh_layout: MeshLayout,
}

impl Default for Settings {
    fn default() -> Self {
        Settings { max_depth: 3, background: Vec3::ZERO, max_distance: 1.0e5, mesh_layout: MeshLayout::Full }
    }
}

/// A light source. Intensities are >= 0 and may exceed 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Uniform ambient light.
    Ambient {
        /// Intensity, >= 0.
        intensity: f32,
    },
    /// A point light at `position` with RGB `color` in [0, 1].
    Point {
        /// Position, scene units.
        position: Vec3,
        /// Intensity, >= 0.
        intensity: f32,
        /// RGB colour, each channel in [0, 1].
        color: Vec3,
    },
    /// A light at infinity shining along `direction` (unit; from the light into the scene).
    Directional {
        /// Unit direction the light travels in (from the light into the scene).
        direction: Vec3,
        /// Intensity, >= 0.
        intensity: f32,
        /// RGB colour, each channel in [0, 1].
        color: Vec3,
    },
}

/// A Phong material with mirror reflection and refraction.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name in the scene file.
    pub name: String,
    /// RGB colour, each channel in [0, 1].
    pub color: Vec3,
    /// Ambient coefficient, >= 0.
    pub ka: f32,
    /// Diffuse coefficient, >= 0.
    pub kd: f32,
    /// Specular coefficient, >= 0.
    pub ks: f32,
    /// Phong exponent (> 0); `None` means no highlight.
    pub shininess: Option<f32>,
    /// Fraction of light from the mirror direction, in [0, 1].
    pub reflectivity: f32,
    /// Fraction of light transmitted by refraction, in [0, 1].
    pub transparency: f32,
    /// Index of refraction of the inside (>= 1 typically; > 0).
    pub ior: f32,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            color: Vec3::splat(0.8),
            ka: 1.0,
            kd: 1.0,
            ks: 0.0,
            shininess: None,
            reflectivity: 0.0,
            transparency: 0.0,
            ior: 1.0,
        }
    }
}

/// Everything needed to render an image.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// Render settings.
    pub settings: Settings,
    /// Lights, in file order.
    pub lights: Vec<Light>,
    /// Materials; objects refer to them by index. Never empty (a default is added).
    pub materials: Vec<Material>,
    /// Top-level objects.
    pub objects: Vec<Object>,
}

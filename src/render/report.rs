//! One scene rendered in one representation, with the report `toolkit render` prints: the
//! geometry built by the plan ([`crate::plan::build_scene`]), the frame, and how each
//! object was traced. Used by the commands, the compare experiment's hard cases and the
//! tests.

use std::fmt::Write as _;

use crate::geometry::Geometry;
use crate::plan::{Representation, build_scene};
use crate::render::{Frame, PrimaryVisibility, render_with};
use crate::scene::Scene;

/// A rendered scene with a printable summary.
pub struct RenderReport {
    /// The frame.
    pub frame: Frame,
    /// Bytes used by the geometry (objects, BVH).
    pub geometry_bytes: usize,
    /// Human-readable report: how each object is traced, time, rays/s, steps per ray.
    pub text: String,
}

/// Renders a loaded scene in a representation and describes the result.
pub fn render_scene(scene: &Scene, repr: Representation) -> RenderReport {
    render_scene_with(scene, repr, PrimaryVisibility::Trace)
}

/// [`render_scene`] with primary visibility traced or rasterized.
pub fn render_scene_with(scene: &Scene, repr: Representation, primary: PrimaryVisibility) -> RenderReport {
    let geometry = build_scene(scene, repr);
    let frame = render_with(scene, &geometry, primary);
    let mut text = String::new();
    for o in geometry.objects() {
        let _ = writeln!(text, "  {}", o.describe());
    }
    let s = &frame.stats;
    let _ = writeln!(
        text,
        "{}x{} depth {} repr {}: frame {:.1} ms, {} rays ({} shadow), {:.2} Mrays/s, {:.2} march steps/ray, \
         {:.2} steps/marched ray, {:.2} BVH nodes/ray, {:.2} primitive tests/ray, {} step-limit misses, \
         geometry {} bytes",
        scene.camera.width,
        scene.camera.height,
        scene.settings.max_depth,
        repr.name(),
        frame.time.as_secs_f64() * 1e3,
        s.rays,
        s.shadow_rays,
        frame.mrays_per_s(),
        frame.steps_per_ray(),
        s.march_steps as f64 / s.marched_rays.max(1) as f64,
        frame.nodes_per_ray(),
        s.prim_tests as f64 / s.rays.max(1) as f64,
        s.step_limit_hits,
        geometry.bytes_used(),
    );
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    if let Some(p) = frame.primary {
        let shading = ms(frame.time) - ms(p);
        let _ = match frame.raster {
            Some(r) => writeln!(
                text,
                "primary visibility rasterized: {:.1} ms (visibility buffer {:.1} ms, hit records {:.1} ms), \
                 shading {shading:.1} ms",
                ms(p),
                ms(r),
                ms(p) - ms(r)
            ),
            None => writeln!(text, "primary visibility traced: {:.1} ms, shading {shading:.1} ms", ms(p)),
        };
    }
    RenderReport { geometry_bytes: geometry.bytes_used(), frame, text }
}

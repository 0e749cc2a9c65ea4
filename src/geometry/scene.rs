//! The whole scene as one [`Geometry`]: a top-level BVH over the bounded objects and a list
//! of unbounded ones (infinite planes, unbounded repetition), so the tracer sees one
//! geometry whatever the representation of each object.

use glam::DVec3;
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;

use crate::geometry::bvh2;
use crate::geometry::{Aabb, Census, Geometry, Hit, Ray, RayStats};

/// The whole scene as one geometry: a top-level BVH over the bounded objects plus a list of
/// unbounded ones (infinite planes, unbounded repetition) that every ray tests.
pub struct SceneGeometry {
    objects: Vec<Box<dyn Geometry>>,
    bvh: Bvh2,
    /// Indices into `objects` of unbounded objects.
    unbounded: Vec<u32>,
    /// For each BVH primitive, the index into `objects`.
    bounded: Vec<u32>,
}

impl SceneGeometry {
    /// Builds the top-level BVH over `objects`.
    pub fn new(objects: Vec<Box<dyn Geometry>>) -> Self {
        let mut boxes = Vec::new();
        let mut bounded = Vec::new();
        let mut unbounded = Vec::new();
        for (i, o) in objects.iter().enumerate() {
            match o.bounds() {
                Some(b) => {
                    boxes.push(b);
                    bounded.push(i as u32);
                }
                None => unbounded.push(i as u32),
            }
        }
        let bvh = bvh2::build(&boxes, BvhBuildParams::medium_build());
        SceneGeometry { objects, bvh, unbounded, bounded }
    }

    /// The objects, in scene order.
    pub fn objects(&self) -> &[Box<dyn Geometry>] {
        &self.objects
    }
}

impl Geometry for SceneGeometry {
    fn bounds(&self) -> Option<Aabb> {
        if !self.unbounded.is_empty() {
            return None;
        }
        self.objects.iter().filter_map(|o| o.bounds()).reduce(|a, b| a.union(&b))
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        for &i in &self.unbounded {
            if let Some(h) = self.objects[i as usize].closest_hit(ray, t_min, t_best, stats) {
                t_best = h.t;
                best = Some(h);
            }
        }
        bvh2::traverse(&self.bvh, ray, t_min, t_best, stats, |prim, t_max, stats| {
            let obj = &self.objects[self.bounded[prim as usize] as usize];
            Ok(obj.closest_hit(ray, t_min, t_max, stats).map(|h| {
                let t = h.t;
                best = Some(h);
                t
            }))
        });
        best
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        if self.unbounded.iter().any(|&i| self.objects[i as usize].any_hit(ray, t_min, t_max, stats)) {
            return true;
        }
        bvh2::traverse_any(&self.bvh, ray, t_min, t_max, stats, |prim, t_max, stats| {
            self.objects[self.bounded[prim as usize] as usize].any_hit(ray, t_min, t_max, stats)
        })
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self
                .objects
                .iter()
                .map(|o| o.bytes_used() + std::mem::size_of::<Box<dyn Geometry>>())
                .sum::<usize>()
            + bvh2::bytes_used(&self.bvh)
            + 4 * (self.unbounded.len() + self.bounded.len())
    }

    fn describe(&self) -> String {
        format!("{} objects, top-level BVH of {} nodes", self.objects.len(), self.bvh.nodes.len())
    }

    fn census(&self) -> Census {
        let own = Census {
            accel_bytes: (bvh2::bytes_used(&self.bvh) + 4 * (self.unbounded.len() + self.bounded.len()))
                as u64,
            ..Census::default()
        };
        self.objects.iter().fold(own, |c, o| c + o.census())
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        let mut best = f64::INFINITY;
        for &i in &self.unbounded {
            best = best.min(self.objects[i as usize].surface_distance(p));
        }
        // Bounded objects nearest first through the top-level BVH, which skips every
        // subtree whose box is farther than the best so far.
        let bounded = bvh2::nearest(&self.bvh, p, |prim| {
            self.objects[self.bounded[prim as usize] as usize].surface_distance(p)
        });
        best.min(bounded)
    }
}

//! The whole scene as one [`Geometry`]: a top-level BVH over the bounded objects and a list
//! of unbounded ones (infinite planes, unbounded repetition), so the tracer sees one
//! geometry whatever the representation of each object. An object made of instances (the
//! copies of a repetition, [`Geometry::instances`]) puts each copy under the top-level
//! BVH; data several objects share ([`Geometry::shared`]: one mesh and BVH placed many
//! times) is counted once in [`SceneGeometry`]'s bytes and census.

use glam::DVec3;
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;

use crate::geometry::bvh2;
use crate::geometry::{
    Aabb, Census, Geometry, Hit, PACKET, Ray, RayStats, Shared, any_hits_one_by_one, closest_hits_one_by_one,
};

/// [`SceneGeometry`]'s `part` of a BVH leaf that is a whole object, not one of its instances.
const WHOLE: u32 = u32::MAX;

/// The whole scene as one geometry: a top-level BVH over the bounded objects plus a list of
/// unbounded ones (infinite planes, unbounded repetition) that every ray tests.
pub struct SceneGeometry {
    objects: Vec<Box<dyn Geometry>>,
    bvh: Bvh2,
    /// Indices into `objects` of unbounded objects.
    unbounded: Vec<u32>,
    /// For each BVH primitive, the index into `objects`.
    bounded: Vec<u32>,
    /// For each BVH primitive, the index into its object's [`Geometry::instances`], or
    /// [`WHOLE`]; empty when no object has instances (then every leaf is a whole object).
    part: Vec<u32>,
    /// Whether any object prefers packets ([`Geometry::prefers_packets`]), decided once.
    packets: bool,
    /// What [`Geometry::describe`] says when this is one object's parts (the copies of an
    /// instanced grid), not a whole scene.
    label: Option<String>,
}

impl SceneGeometry {
    /// The bounded objects (BVH leaves) that `rays` (each with its `t_max`; `None` for a
    /// ray to leave out) reach within their intervals, each once, for a packet query, with
    /// the rays that reach each (bit `k` for ray `k`); `None` when they are more than
    /// [`PACKET_CANDIDATES`] (the caller then goes ray by ray).
    fn packet_leaves<'r>(
        &self,
        rays: impl Iterator<Item = Option<(&'r Ray, f32)>>,
        t_min: f32,
        stats: &mut RayStats,
    ) -> Option<Candidates> {
        let mut c = Candidates { prims: [0; PACKET_CANDIDATES], rays: [0; PACKET_CANDIDATES], count: 0 };
        let mut overflow = false;
        for (k, ray) in rays.enumerate() {
            let Some((ray, reach)) = ray else { continue };
            bvh2::traverse(&self.bvh, ray, t_min, reach, stats, |prim, _, _| {
                let at = match c.prims[..c.count].iter().position(|&p| p == prim) {
                    Some(at) => at,
                    None if c.count == PACKET_CANDIDATES => {
                        overflow = true;
                        return Err(());
                    }
                    None => {
                        c.prims[c.count] = prim;
                        c.count += 1;
                        c.count - 1
                    }
                };
                c.rays[at] |= 1 << k;
                Ok(None)
            });
            if overflow {
                return None;
            }
        }
        Some(c)
    }
    /// The closest hit among the bounded objects (front to back through the BVH).
    fn bounded_closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let mut best = None;
        bvh2::traverse(&self.bvh, ray, t_min, t_max, stats, |prim, t_max, stats| {
            Ok(self.leaf(prim).closest_hit(ray, t_min, t_max, stats).map(|h| {
                let t = h.t;
                best = Some(h);
                t
            }))
        });
        best
    }

    /// Whether any bounded object is hit (through the BVH, stopping at the first).
    fn bounded_any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        bvh2::traverse_any(&self.bvh, ray, t_min, t_max, stats, |prim, t_max, stats| {
            self.leaf(prim).any_hit(ray, t_min, t_max, stats)
        })
    }

    /// Builds the top-level BVH over `objects`.
    pub fn new(objects: Vec<Box<dyn Geometry>>) -> Self {
        let mut boxes = Vec::new();
        let mut bounded = Vec::new();
        let mut unbounded = Vec::new();
        let mut part = Vec::new();
        for (i, o) in objects.iter().enumerate() {
            if !o.instances().is_empty() {
                for (k, instance) in o.instances().iter().enumerate() {
                    if let Some(b) = instance.bounds() {
                        boxes.push(b);
                        bounded.push(i as u32);
                        part.push(k as u32);
                    }
                }
                continue;
            }
            match o.bounds() {
                Some(b) => {
                    boxes.push(b);
                    bounded.push(i as u32);
                    part.push(WHOLE);
                }
                None => unbounded.push(i as u32),
            }
        }
        if part.iter().all(|&k| k == WHOLE) {
            part = Vec::new();
        }
        let bvh = bvh2::build(&boxes, BvhBuildParams::medium_build());
        // One bounded object takes its batches as batches (a mesh traces them in packets)
        // whatever it prefers: no front-to-back order among objects to lose.
        let packets = objects.iter().any(|o| o.prefers_packets()) || bounded.len() == 1;
        SceneGeometry { objects, bvh, unbounded, bounded, part, packets, label: None }
    }

    /// `objects` as the parts of one object (the copies of an instanced grid) under a BVH of
    /// their own, described by `label`.
    pub fn labelled(objects: Vec<Box<dyn Geometry>>, label: String) -> Self {
        SceneGeometry { label: Some(label), ..Self::new(objects) }
    }

    /// The geometry of top-level BVH primitive `prim`: an object or one of its instances.
    #[inline]
    fn leaf(&self, prim: u32) -> &dyn Geometry {
        let object = &*self.objects[self.bounded[prim as usize] as usize];
        match self.part.get(prim as usize) {
            Some(&k) if k != WHOLE => &object.instances()[k as usize],
            _ => object,
        }
    }

    /// The shared data counted more than once in the objects' bytes and census: every
    /// [`Geometry::shared`] after the first with the same id.
    fn repeated_shares(&self) -> Vec<Shared> {
        let mut all: Vec<Shared> = self.objects.iter().filter_map(|o| o.shared()).collect();
        all.sort_by_key(|s| s.id);
        let mut repeated = Vec::new();
        for w in all.windows(2) {
            if w[0].id == w[1].id {
                repeated.push(w[1]);
            }
        }
        repeated
    }

    /// Bytes of the top-level structure: the BVH and the leaf and unbounded lists.
    fn own_accel_bytes(&self) -> usize {
        bvh2::bytes_used(&self.bvh) + 4 * (self.unbounded.len() + self.bounded.len() + self.part.capacity())
    }

    /// The objects, in scene order.
    pub fn objects(&self) -> &[Box<dyn Geometry>] {
        &self.objects
    }
}

/// The bounded objects a packet's rays reach ([`SceneGeometry::packet_leaves`]).
struct Candidates {
    /// BVH primitives, in the order the rays reached them.
    prims: [u32; PACKET_CANDIDATES],
    /// Per primitive, the rays that reach it (bit `k` for ray `k` of the packet).
    rays: [u8; PACKET_CANDIDATES],
    count: usize,
}

/// Most bounded objects a packet marches together ([`SceneGeometry`]'s
/// [`Geometry::closest_hits`]); a packet whose rays reach more goes ray by ray.
const PACKET_CANDIDATES: usize = 32;

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
        self.bounded_closest_hit(ray, t_min, t_best, stats).or(best)
    }

    fn prefers_packets(&self) -> bool {
        self.packets
    }

    /// Batches go ray by ray (front to back through the top-level BVH, as
    /// [`Geometry::closest_hit`]) unless an object prefers packets or the scene has one
    /// bounded object. Then the unbounded objects take the whole batch, and so does the
    /// bounded leaf of a scene with just one (without a trip through the BVH, which could
    /// only test the leaf's own bounds). Several bounded leaves take the batch in packets
    /// of [`PACKET`] consecutive rays: each leaf (object or instance) that any ray of a
    /// packet reaches takes the rays of the packet that reach it (the others' reach set
    /// below `t_min`; up to 32 leaves, else the packet goes ray by ray
    /// through the BVH). Nearest hits compose through `t_max`.
    fn closest_hits(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &mut [f32],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) {
        if !self.prefers_packets() {
            return closest_hits_one_by_one(self, rays, t_min, t_max, hits, stats);
        }
        for &i in &self.unbounded {
            self.objects[i as usize].closest_hits(rays, t_min, t_max, hits, stats);
        }
        match self.bounded.len() {
            0 => {}
            1 => self.leaf(0).closest_hits(rays, t_min, t_max, hits, stats),
            _ => {
                let packets = rays.chunks(PACKET).zip(t_max.chunks_mut(PACKET)).zip(hits.chunks_mut(PACKET));
                for ((rays, t_max), hits) in packets {
                    let reach = rays.iter().zip(t_max.iter().copied()).map(Some);
                    let Some(c) = self.packet_leaves(reach, t_min, stats) else {
                        for ((ray, t_max), hit) in rays.iter().zip(t_max.iter_mut()).zip(hits.iter_mut()) {
                            if let Some(h) = self.bounded_closest_hit(ray, t_min, *t_max, stats) {
                                (*t_max, *hit) = (h.t, Some(h));
                            }
                        }
                        continue;
                    };
                    let all = (1u8 << (rays.len() - 1) << 1).wrapping_sub(1);
                    for (&prim, &reached) in c.prims[..c.count].iter().zip(&c.rays) {
                        if reached == all {
                            self.leaf(prim).closest_hits(rays, t_min, t_max, hits, stats);
                            continue;
                        }
                        // Only the rays that reach the object's box, as one by one: the
                        // others' reach is below `t_min`, so they cannot hit.
                        let mut reach = [f32::NEG_INFINITY; PACKET];
                        for (k, r) in reach.iter_mut().enumerate().take(rays.len()) {
                            if reached & (1 << k) != 0 {
                                *r = t_max[k];
                            }
                        }
                        self.leaf(prim).closest_hits(rays, t_min, &mut reach[..rays.len()], hits, stats);
                        for (k, t) in t_max.iter_mut().enumerate() {
                            if reached & (1 << k) != 0 {
                                *t = reach[k];
                            }
                        }
                    }
                }
            }
        }
    }

    /// As [`Self::closest_hits`], for the rays not yet occluded; a leaf is skipped once
    /// every ray of its packet is.
    fn any_hits(&self, rays: &[Ray], t_min: f32, t_max: &[f32], occluded: &mut [bool], stats: &mut RayStats) {
        if !self.prefers_packets() {
            return any_hits_one_by_one(self, rays, t_min, t_max, occluded, stats);
        }
        for &i in &self.unbounded {
            self.objects[i as usize].any_hits(rays, t_min, t_max, occluded, stats);
        }
        match self.bounded.len() {
            0 => {}
            1 => {
                if !occluded.iter().all(|&o| o) {
                    self.leaf(0).any_hits(rays, t_min, t_max, occluded, stats);
                }
            }
            _ => {
                let packets = rays.chunks(PACKET).zip(t_max.chunks(PACKET)).zip(occluded.chunks_mut(PACKET));
                for ((rays, t_max), occluded) in packets {
                    let live = rays.iter().zip(t_max.iter().copied()).zip(occluded.iter());
                    let live = live.map(|(r, o)| (!*o).then_some(r));
                    let Some(c) = self.packet_leaves(live, t_min, stats) else {
                        for ((ray, &t_max), occluded) in rays.iter().zip(t_max).zip(occluded.iter_mut()) {
                            *occluded = *occluded || self.bounded_any_hit(ray, t_min, t_max, stats);
                        }
                        continue;
                    };
                    for (&prim, &reached) in c.prims[..c.count].iter().zip(&c.rays) {
                        if occluded.iter().all(|&o| o) {
                            break;
                        }
                        // Only the rays that reach the object's box, as one by one: the
                        // others go in as already occluded, and keep their own state.
                        let mut blocked = [true; PACKET];
                        for (k, b) in blocked.iter_mut().enumerate().take(rays.len()) {
                            *b = occluded[k] || reached & (1 << k) == 0;
                        }
                        self.leaf(prim).any_hits(rays, t_min, t_max, &mut blocked[..rays.len()], stats);
                        for (k, o) in occluded.iter_mut().enumerate() {
                            *o = *o || (reached & (1 << k) != 0 && blocked[k]);
                        }
                    }
                }
            }
        }
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.unbounded.iter().any(|&i| self.objects[i as usize].any_hit(ray, t_min, t_max, stats))
            || self.bounded_any_hit(ray, t_min, t_max, stats)
    }

    /// Every object's bytes (shared data once) and the top-level structure's.
    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.label.as_ref().map_or(0, String::capacity)
            + self
                .objects
                .iter()
                .map(|o| o.bytes_used() + std::mem::size_of::<Box<dyn Geometry>>())
                .sum::<usize>()
            - self.repeated_shares().iter().map(|s| s.bytes).sum::<usize>()
            + self.own_accel_bytes()
    }

    fn describe(&self) -> String {
        if let Some(label) = &self.label {
            return label.clone();
        }
        let instances: usize = self.objects.iter().map(|o| o.instances().len()).sum();
        if instances == 0 {
            return format!(
                "{} objects, top-level BVH of {} nodes",
                self.objects.len(),
                self.bvh.nodes.len()
            );
        }
        format!(
            "{} objects ({instances} instances), top-level BVH of {} nodes",
            self.objects.len(),
            self.bvh.nodes.len()
        )
    }

    /// Every object's census (shared data once) and the top-level structure's bytes.
    fn census(&self) -> Census {
        let own = Census { accel_bytes: self.own_accel_bytes() as u64, ..Census::default() };
        let all = self.objects.iter().fold(own, |c, o| c + o.census());
        self.repeated_shares().iter().fold(all, |c, s| c - s.census)
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        let mut best = f64::INFINITY;
        for &i in &self.unbounded {
            best = best.min(self.objects[i as usize].surface_distance(p));
        }
        // Bounded objects nearest first through the top-level BVH, which skips every
        // subtree whose box is farther than the best so far.
        let bounded = bvh2::nearest(&self.bvh, p, |prim| self.leaf(prim).surface_distance(p));
        best.min(bounded)
    }
}

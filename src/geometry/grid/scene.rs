//! One narrow-band grid shared by every gridded object of a scene ([`SceneGrid`]): a
//! single world-space lattice at one voxel size, bricks stored only near some surface, so
//! its bytes grow with the scenes' surface at that voxel size, not with the number of
//! objects (each object's own grid pays its margins and its empty bricks, and close
//! objects share bricks here). The field is the union (minimum) of the objects' distances;
//! the material at a point is that of the nearest object, stored once per brick where one
//! material is near, and per sample only in bricks where several are.
//!
//! Every object that shares the grid is traced as a [`SceneGridObject`]: the one marcher
//! over the shared field, clipped to that object's box (plus the grid's margin), so the
//! scene's top-level BVH over the objects' boxes is the hierarchy over occupied space and
//! the band's chessboard skipping crosses the empty bricks inside a box. A ray marched in
//! one object's box may meet a neighbour's surface where the neighbour reaches into the
//! box: that is the same surface, at the same distance, with the neighbour's material.
//! The grid is counted once in a scene's bytes ([`Geometry::shared`](crate::geometry::Geometry::shared)).
//!
//! The builder, which samples the objects' distances into the bricks, is a conversion:
//! `convert::mesh_to_grid::band::band_from_members`.

use std::sync::Arc;

use glam::{DVec3, UVec3, Vec3};

use super::band::{BRICK, BRICK_SAMPLES, BS, BandGrid};
use super::object::{GRID_STEP_SCALE, GridStore};
use crate::geometry::march::MarchParams;
use crate::geometry::marched::{
    DistanceField, FieldFacts, FieldObject, Marched, PointBlock, Storage, SurfacePoint,
};
use crate::geometry::{Aabb, Census, MaterialId, PACKET, Shared, aabb, box_distance, distance_by_projection};

/// `brick_material` entry bit of a brick whose samples name their material one by one.
const MIXED: u32 = 1 << 31;
/// `brick_material` entry bits of a brick with two materials (a bit mask per sample).
const PAIR: u32 = 1 << 30;
/// Words of a per-sample bit mask.
const MASK_WORDS: usize = BRICK_SAMPLES.div_ceil(64);

/// A narrow-band grid of the union of several objects, with each point's material (see
/// the module documentation).
#[derive(Debug)]
pub struct SceneGrid {
    /// The union's distances: world-space lattice, bricks near any surface (always a
    /// [`GridStore::Band`], held as a store for its AVX2 build of the marched distance).
    grid: GridStore,
    /// The materials of the objects, indexed by the `u16` entries below.
    materials: Vec<MaterialId>,
    /// Per stored brick (the band's slot order): an index into `materials`, or `MIXED |
    /// k` for the `k`-th entry of `mixed`.
    brick_material: Vec<u32>,
    /// Per brick with two materials near its surface: `(first, second, mask)`, the mask's
    /// bit `s` set where sample `s` (x fastest) takes the second.
    pairs: Vec<(u16, u16, [u64; MASK_WORDS])>,
    /// Per brick with more: the nearest object's material per sample, [`BRICK_SAMPLES`]
    /// each, x fastest.
    sample_material: Vec<u16>,
    /// Number of objects sampled into the grid.
    objects: usize,
}

/// The material of one stored brick, as the builder finds it.
#[derive(Clone, Debug, PartialEq)]
pub enum BrickMaterial {
    /// Every sample's nearest object has this material (an index into the grid's
    /// materials).
    One(u16),
    /// The nearest object's material per sample ([`BRICK_SAMPLES`] indices, x fastest).
    PerSample(Vec<u16>),
}

impl BrickMaterial {
    /// The compact form of a brick's per-sample materials `table` ([`BRICK_SAMPLES`]
    /// indices): only samples where `near[s]` (near a surface) count; the others take a
    /// material that is near. [`BrickMaterial::One`] when one material is near.
    pub fn compact(table: &[u16], near: &[bool]) -> BrickMaterial {
        let mut seen: Vec<u16> = table.iter().zip(near).filter(|(_, n)| **n).map(|(m, _)| *m).collect();
        seen.sort_unstable();
        seen.dedup();
        match seen.as_slice() {
            [] => BrickMaterial::One(table[0]),
            [m] => BrickMaterial::One(*m),
            _ => BrickMaterial::PerSample(
                table.iter().zip(near).map(|(&m, &n)| if n { m } else { seen[0] }).collect(),
            ),
        }
    }
}

impl SceneGrid {
    /// The grid of `objects` objects from the band of their union `band`, the materials
    /// the indices below name, and per stored brick of `band` (slot order) its material.
    ///
    /// # Panics
    /// When `bricks` does not have one entry per stored brick of `band`, or a table is
    /// not [`BRICK_SAMPLES`] long.
    pub fn new(
        band: BandGrid,
        materials: Vec<MaterialId>,
        bricks: Vec<BrickMaterial>,
        objects: usize,
    ) -> Self {
        assert_eq!(bricks.len(), band.stored_bricks(), "one material entry per stored brick");
        let mut brick_material = Vec::with_capacity(bricks.len());
        let mut pairs = Vec::new();
        let mut sample_material = Vec::new();
        for b in bricks {
            match b {
                BrickMaterial::One(m) => brick_material.push(m as u32),
                BrickMaterial::PerSample(table) => {
                    assert_eq!(table.len(), BRICK_SAMPLES, "a material per sample");
                    let first = table[0];
                    let second = table.iter().copied().find(|&m| m != first).unwrap_or(first);
                    if table.iter().all(|&m| m == first || m == second) {
                        let mut mask = [0u64; MASK_WORDS];
                        for (s, &m) in table.iter().enumerate() {
                            mask[s / 64] |= ((m == second && m != first) as u64) << (s % 64);
                        }
                        brick_material.push(PAIR | pairs.len() as u32);
                        pairs.push((first, second, mask));
                    } else {
                        brick_material.push(MIXED | (sample_material.len() / BRICK_SAMPLES) as u32);
                        sample_material.extend_from_slice(&table);
                    }
                }
            }
        }
        pairs.shrink_to_fit();
        sample_material.shrink_to_fit();
        let grid = GridStore::Band(band);
        SceneGrid { grid, materials, brick_material, pairs, sample_material, objects }
    }

    /// The union's band grid.
    pub fn band(&self) -> &BandGrid {
        match &self.grid {
            GridStore::Band(b) => b,
            GridStore::Dense(_) => unreachable!("a scene grid is a band"),
        }
    }

    /// Number of objects sampled into the grid.
    pub fn objects(&self) -> usize {
        self.objects
    }

    /// Number of stored bricks with more than one material near their surface.
    pub fn mixed_bricks(&self) -> usize {
        self.pairs.len() + self.sample_material.len() / BRICK_SAMPLES
    }

    /// The material at world point `p`: the nearest object's at the sample nearest `p` in
    /// a stored brick; the first object's elsewhere (no surface is there).
    pub fn material(&self, p: Vec3) -> MaterialId {
        let b = self.band();
        let (lo, hi) = b.bounds();
        let f = (p.clamp(lo, hi) - b.origin) / b.voxel;
        let cell = f.floor().clamp(Vec3::ZERO, (b.dims - UVec3::splat(2)).as_vec3()).as_uvec3();
        let Some(slot) = b.slot(cell / BRICK) else { return self.materials[0] };
        let m = self.brick_material[slot];
        // The sample nearest `p`, in the brick's own sample order.
        let sample = || {
            let local = (f - (cell / BRICK * BRICK).as_vec3()).round().as_uvec3().min(UVec3::splat(BRICK));
            local.x as usize + BS * (local.y as usize + BS * local.z as usize)
        };
        let index = if m & MIXED != 0 {
            self.sample_material[(m & !MIXED) as usize * BRICK_SAMPLES + sample()]
        } else if m & PAIR != 0 {
            let (first, second, mask) = &self.pairs[(m & !PAIR) as usize];
            let s = sample();
            if mask[s / 64] >> (s % 64) & 1 == 1 { *second } else { *first }
        } else {
            m as u16
        };
        self.materials[index as usize]
    }

    /// Bytes held: the band, the material tables and the struct.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.grid.bytes_used() - std::mem::size_of::<GridStore>()
            + self.materials.capacity() * std::mem::size_of::<MaterialId>()
            + self.brick_material.capacity() * 4
            + self.pairs.capacity() * std::mem::size_of::<(u16, u16, [u64; MASK_WORDS])>()
            + self.sample_material.capacity() * 2
    }
}

/// One object of a [`SceneGrid`]: the one marcher over the shared field, clipped to the
/// object's box.
pub type SceneGridObject = Marched<SceneGridField>;

/// The field of a [`SceneGridObject`]: the shared grid's marched distance (empty-space
/// skipping in empty bricks, as a band's), with steps scaled by [`GRID_STEP_SCALE`].
pub struct SceneGridField {
    grid: Arc<SceneGrid>,
}

impl SceneGridObject {
    /// The object of `grid` whose box is `bounds` (world space; clipped to the grid's box),
    /// marched with `march`.
    pub fn new(grid: Arc<SceneGrid>, bounds: Aabb, march: MarchParams, label: String) -> Self {
        let (lo, hi) = grid.band().bounds();
        let b = bounds.intersection(&aabb(lo, hi));
        let size = (Vec3::from(b.max) - Vec3::from(b.min)).length().max(grid.band().voxel) as f64;
        Marched::from_field(SceneGridField { grid }, Some(b), size, march, label)
    }
}

impl DistanceField for SceneGridField {
    #[inline]
    fn distance(&self, p: DVec3, _tolerance: f64) -> f64 {
        self.grid.grid.march_distance(p.as_vec3()) as f64 * GRID_STEP_SCALE
    }

    /// Packet by packet, the band interpolating eight points in one 8-wide kernel
    /// ([`BandGrid::march_distance8`]), each lane its scalar value.
    #[inline]
    fn distances<const W: usize>(&self, block: &mut PointBlock<W>) {
        let packets = block.packets();
        for g in 0..W / PACKET {
            if packets & 1 << g == 0 {
                continue;
            }
            let points = block.packet_points(g);
            let xs = points.map(|p| p.x as f32);
            let ys = points.map(|p| p.y as f32);
            let zs = points.map(|p| p.z as f32);
            let v = self.grid.grid.march_distance8(&xs, &ys, &zs);
            for (x, v) in block.out[PACKET * g..PACKET * (g + 1)].iter_mut().zip(v) {
                *x = v as f64 * GRID_STEP_SCALE;
            }
        }
    }

    /// Signed, not exact (the interpolation of exact samples is not itself a distance),
    /// in packets (the band interpolates eight points in one 8-wide kernel).
    fn facts(&self) -> FieldFacts {
        FieldFacts { signed: true, exact: false, packets: true, refills_lanes: true }
    }

    /// Half a voxel for the normal, as a grid object's (the interpolant is piecewise);
    /// the material of the band at `p`.
    fn surface(&self, p: DVec3, _eps: f64) -> SurfacePoint {
        SurfacePoint {
            normal_step: 0.5 * self.grid.band().voxel as f64,
            material: self.grid.material(p.as_vec3()),
        }
    }
}

/// One object's share of the scene grid; its error measured on the interpolated surface.
impl FieldObject for SceneGridField {
    fn storage(&self) -> Storage {
        let census = Census { triangles: 0, grid_samples: self.grid.band().stored_values(), accel_bytes: 0 };
        Storage {
            heap_bytes: self.grid.bytes_used(),
            census,
            shared: Some(Shared::of(&self.grid, self.grid.bytes_used(), census)),
        }
    }

    fn surface_distance(&self, p: DVec3, _size: f64) -> f64 {
        // As a grid object's: from the nearest box point, by projection onto the
        // interpolated surface.
        let (lo, hi) = self.grid.band().bounds();
        let outside = box_distance(&aabb(lo, hi), p);
        let q = p.clamp(lo.as_dvec3(), hi.as_dvec3());
        let f = |x: DVec3| self.grid.band().trilinear(x.as_vec3()) as f64;
        let h = 0.25 * self.grid.band().voxel as f64;
        outside + distance_by_projection(&f, q, h, 1e-6 * (hi - lo).length() as f64)
    }

    fn describe(&self, label: &str) -> String {
        let b = self.grid.band();
        format!(
            "{label}: one of {} objects sharing a scene grid {}x{}x{} samples, narrow band of {} cells \
             ({} of {} bricks stored, {} with several materials), voxel {:.5}, ray marched",
            self.grid.objects,
            b.dims.x,
            b.dims.y,
            b.dims.z,
            b.band_cells,
            b.stored_bricks(),
            b.brick_count(),
            self.grid.mixed_bricks(),
            b.voxel
        )
    }
}

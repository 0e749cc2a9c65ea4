//! Marching cubes with a generated, face-consistent case table (asymptotic decider on
//! ambiguous faces; diagonals only on upper faces), so the output is closed and
//! edge-manifold by construction.

use super::*;

/// The marching cubes case table: per cube configuration (bit `c` set when [`corner`] `c`
/// is inside) and choice on each ambiguous face, the surface's polygons as cube edges
/// (numbered as in [`CubeTopology`]). Generated, not typed in: the crossings on each face
/// are paired into segments (on a face with four, the pairing is a per-face choice), the
/// segments are oriented and chained into cycles, and each cycle is triangulated. Every
/// mesh edge between vertices on one cube face is then either a segment, which the two
/// cells sharing the face produce alike (same choice, from the face's corner values only)
/// and in opposite directions, or a diagonal, which only the cell below the face may use
/// (diagonals on a cell's lower faces, x, y or z = 0, are never used); every other mesh
/// edge is inside one cell. So the output is closed and edge-manifold by construction.
///
/// Polygons of 4 to 7 vertices list every allowed triangulation; [`marching_cubes`] takes
/// the one that folds least on the actual vertices (a fold the wrong way turns triangles
/// inside out at sharp edges). Larger ones have one (the shortest diagonals between the
/// edges' midpoints). The few cycles that cannot be triangulated without a diagonal on a
/// lower face (they pass twice through two or three lower faces, all ambiguous) get a
/// vertex of their own at the mean of their crossings, fanned to the cycle.
pub(super) struct McTable {
    /// Per configuration: a bit per ambiguous face (four crossings, corners alternating).
    pub(super) ambiguous: [u8; 256],
    /// Per configuration: the cube edges that change sign.
    pub(super) crossing: [u16; 256],
    /// Per configuration: its first case; the case is this plus the choices on its
    /// ambiguous faces, packed in face order.
    pub(super) first_case: [u16; 257],
    /// Per case: its polygons are `polys[case_start[k]..case_start[k + 1]]`.
    pub(super) case_start: Vec<u16>,
    pub(super) polys: Vec<McPolygon>,
    /// Triangles as cube edges; `MC_CENTRE + j` stands for the case's `j`-th cycle
    /// vertex.
    pub(super) tris: Vec<[u8; 3]>,
    /// Per case: the cube edges (a bit each) of the cycles that get a vertex of their
    /// own, `centres[centre_start[k]..centre_start[k + 1]]`.
    pub(super) centre_start: Vec<u16>,
    pub(super) centres: Vec<u16>,
}

/// One polygon of a case: `options` triangulations of `per` triangles each, one after
/// another in [`McTable`]'s triangles from `first`.
#[derive(Clone, Copy, Debug)]
pub(super) struct McPolygon {
    pub(super) first: u32,
    pub(super) options: u8,
    pub(super) per: u8,
}

/// Index in [`McTable`]'s triangles of the first cycle vertex (after the 12 cube edges).
pub(super) const MC_CENTRE: u8 = 12;

/// Faces `x = 0`, `y = 0`, `z = 0` of a cell, a bit per face (numbered as in
/// [`CubeTopology`]: `2 axis + side`).
pub(super) const LOWER_FACES: u8 = 0b01_0101;

/// Polygons up to this many vertices list all their allowed triangulations (42 for 7).
pub(super) const MC_OPTIONS_UP_TO: usize = 7;

/// The table, built on first use.
pub(super) fn mc_table() -> &'static McTable {
    static TABLE: std::sync::OnceLock<McTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(McTable::new)
}

/// Every triangulation of the polygon `0..m` as triangles `[i, j, k]` with `i < j < k`.
pub(super) fn polygon_triangulations(m: usize) -> Vec<Vec<[usize; 3]>> {
    pub(super) fn between(i: usize, j: usize) -> Vec<Vec<[usize; 3]>> {
        if j < i + 2 {
            return vec![Vec::new()];
        }
        let mut all = Vec::new();
        for k in i + 1..j {
            for left in between(i, k) {
                for right in between(k, j) {
                    let mut t = vec![[i, k, j]];
                    t.extend(&left);
                    t.extend(&right);
                    all.push(t);
                }
            }
        }
        all
    }
    between(0, m - 1)
}

impl McTable {
    pub(super) fn new() -> McTable {
        let topo = CubeTopology::new();
        let mut table = McTable {
            ambiguous: [0; 256],
            crossing: [0; 256],
            first_case: [0; 257],
            case_start: Vec::new(),
            polys: Vec::new(),
            tris: Vec::new(),
            centre_start: Vec::new(),
            centres: Vec::new(),
        };
        let triangulations: Vec<Vec<Vec<[usize; 3]>>> = (0..=MC_OPTIONS_UP_TO)
            .map(|m| if m >= 3 { polygon_triangulations(m) } else { Vec::new() })
            .collect();
        for config in 0..256usize {
            let inside = |c: usize| (config >> c) & 1 != 0;
            for (k, &(c, d)) in topo.edges.iter().enumerate() {
                if inside(c) != inside(c | 1 << d) {
                    table.crossing[config] |= 1 << k;
                }
            }
            for (fi, (corners, _)) in topo.faces.iter().enumerate() {
                let s = corners.map(inside);
                if s[0] == s[2] && s[1] == s[3] && s[0] != s[1] {
                    table.ambiguous[config] |= 1 << fi;
                }
            }
            table.first_case[config] = table.case_start.len() as u16;
            let faces: Vec<usize> = (0..6).filter(|fi| table.ambiguous[config] & (1 << fi) != 0).collect();
            for choice in 0..1usize << faces.len() {
                // Bit set: the face's centre counts as inside (its positive corners are cut
                // off), else its negative corners are cut off.
                let centre_inside =
                    faces.iter().enumerate().fold(0u8, |m, (j, &fi)| m | (((choice >> j) & 1) as u8) << fi);
                table.case_start.push(table.polys.len() as u16);
                table.centre_start.push(table.centres.len() as u16);
                for cycle in Self::cycles(&topo, config, centre_inside) {
                    table.add_cycle(&topo, &cycle, &triangulations);
                }
            }
        }
        table.first_case[256] = table.case_start.len() as u16;
        table.case_start.push(table.polys.len() as u16);
        table.centre_start.push(table.centres.len() as u16);
        table
    }

    /// The surface's cycles of `config` with the ambiguous faces' centres inside where
    /// `centre_inside` has their bit, as cube edges in counter-clockwise order seen from
    /// outside.
    pub(super) fn cycles(topo: &CubeTopology, config: usize, centre_inside: u8) -> Vec<Vec<usize>> {
        let inside = |c: usize| (config >> c) & 1 != 0;
        // Oriented segments: next[a] = b. A segment a -> b on a face with outward normal
        // `nf` that cuts off corner `c` runs so that `(nf x (b - a)) . (c - a)` is negative
        // for an inside `c` (the surface's normal points to positive `f`, and the polygon
        // turns counter-clockwise about it).
        let mut next = [usize::MAX; 12];
        let mut link = |nf: DVec3, a: usize, b: usize, c: usize| {
            let s = nf.cross(edge_mid(topo, b) - edge_mid(topo, a)).dot(corner_pos(c) - edge_mid(topo, a));
            let (a, b) = if (s < 0.0) == inside(c) { (a, b) } else { (b, a) };
            assert_eq!(next[a], usize::MAX, "config {config}: edge {a} starts two segments");
            next[a] = b;
        };
        for (fi, (corners, fe)) in topo.faces.iter().enumerate() {
            let mut nf = DVec3::ZERO;
            nf[fi / 2] = if fi % 2 == 1 { 1.0 } else { -1.0 };
            let on: Vec<usize> =
                (0..4).filter(|&i| inside(corners[i]) != inside(corners[(i + 1) % 4])).collect();
            match on.len() {
                2 => {
                    // Any inside corner of the face lies on the inside of the segment.
                    let c = corners.iter().copied().find(|&c| inside(c)).expect("a face with a crossing");
                    link(nf, fe[on[0]], fe[on[1]], c);
                }
                4 => {
                    // Corner i is cut off by the segment from edge i - 1 to edge i.
                    let cut_inside = centre_inside & (1 << fi) == 0;
                    for i in (0..4).filter(|&i| inside(corners[i]) == cut_inside) {
                        link(nf, fe[(i + 3) % 4], fe[i], corners[i]);
                    }
                }
                _ => {}
            }
        }
        let mut cycles = Vec::new();
        let mut seen = 0u16;
        for start in 0..12 {
            if next[start] == usize::MAX || seen & (1 << start) != 0 {
                continue;
            }
            let mut cycle = Vec::new();
            let mut k = start;
            while seen & (1 << k) == 0 {
                seen |= 1 << k;
                cycle.push(k);
                k = next[k];
                assert_ne!(k, usize::MAX, "config {config}: open chain");
            }
            assert_eq!(k, start, "config {config}: chains merge");
            cycles.push(cycle);
        }
        cycles
    }

    /// Adds the triangulations of `cycle` to the current case.
    pub(super) fn add_cycle(
        &mut self,
        topo: &CubeTopology,
        cycle: &[usize],
        triangulations: &[Vec<Vec<[usize; 3]>>],
    ) {
        let m = cycle.len();
        // Whether the diagonal between cycle vertices i and j may be used (see the type).
        let allowed = |i: usize, j: usize| {
            let adjacent = j == i + 1 || (i == 0 && j == m - 1);
            adjacent || edge_faces(topo, cycle[i]) & edge_faces(topo, cycle[j]) & LOWER_FACES == 0
        };
        let ok =
            |t: &[[usize; 3]]| t.iter().all(|&[i, j, k]| allowed(i, j) && allowed(j, k) && allowed(i, k));
        let first = self.tris.len() as u32;
        let push = |tris: &mut Vec<[u8; 3]>, t: &[[usize; 3]]| {
            tris.extend(t.iter().map(|tri| tri.map(|i| cycle[i] as u8)));
        };
        let options: Vec<&Vec<[usize; 3]>> = if m <= MC_OPTIONS_UP_TO {
            triangulations[m].iter().filter(|t| ok(t)).collect()
        } else {
            Vec::new()
        };
        if !options.is_empty() {
            for t in &options {
                push(&mut self.tris, t);
            }
            self.polys.push(McPolygon { first, options: options.len() as u8, per: (m - 2) as u8 });
            return;
        }
        // One triangulation: the shortest allowed diagonals between the edges' midpoints
        // (dynamic programming over the polygon's sub-chains).
        let chord = |i: usize, j: usize| -> f64 {
            if !allowed(i, j) {
                1e9
            } else if j == i + 1 || (i == 0 && j == m - 1) {
                0.0
            } else {
                (edge_mid(topo, cycle[i]) - edge_mid(topo, cycle[j])).length()
            }
        };
        let mut cost = vec![vec![0.0f64; m]; m];
        let mut split = vec![vec![0usize; m]; m];
        for len in 2..m {
            for i in 0..m - len {
                let j = i + len;
                let (best, at) = (i + 1..j)
                    .map(|k| (cost[i][k] + cost[k][j] + chord(i, k) + chord(k, j), k))
                    .fold((f64::INFINITY, 0), |b, c| if c.0 < b.0 { c } else { b });
                cost[i][j] = best;
                split[i][j] = at;
            }
        }
        if cost[0][m - 1] < 1e9 {
            let mut t = Vec::new();
            let mut stack = vec![(0, m - 1)];
            while let Some((i, j)) = stack.pop() {
                if j >= i + 2 {
                    let k = split[i][j];
                    t.push([i, k, j]);
                    stack.push((i, k));
                    stack.push((k, j));
                }
            }
            push(&mut self.tris, &t);
            self.polys.push(McPolygon { first, options: 1, per: (m - 2) as u8 });
        } else {
            // A fan around a vertex of the cycle's own.
            let case = self.case_start.len() - 1;
            let c = MC_CENTRE + (self.centres.len() - self.centre_start[case] as usize) as u8;
            self.centres.push(cycle.iter().fold(0u16, |mask, &k| mask | 1 << k));
            for i in 0..m {
                self.tris.push([cycle[i] as u8, cycle[(i + 1) % m] as u8, c]);
            }
            self.polys.push(McPolygon { first, options: 1, per: m as u8 });
        }
    }

    /// The case of a cell with inside bits `config` and corner samples `values` (read
    /// only when the configuration has an ambiguous face).
    #[inline]
    pub(super) fn case(&self, topo: &CubeTopology, config: u8, values: impl FnOnce() -> [f32; 8]) -> usize {
        let c = config as usize;
        let mut case = self.first_case[c] as usize;
        let amb = self.ambiguous[c];
        if amb != 0 {
            let v = values();
            let mut j = 0;
            for (fi, (corners, _)) in topo.faces.iter().enumerate() {
                if amb & (1 << fi) != 0 {
                    let [a, b, c, d] = corners.map(|k| v[k] as f64);
                    if face_centre_inside(a, b, c, d) {
                        case += 1 << j;
                    }
                    j += 1;
                }
            }
        }
        case
    }

    /// The polygons of `case`.
    #[inline]
    pub(super) fn polygons(&self, case: usize) -> &[McPolygon] {
        &self.polys[self.case_start[case] as usize..self.case_start[case + 1] as usize]
    }

    /// The triangles of option `o` of polygon `p`.
    #[inline]
    pub(super) fn option(&self, p: McPolygon, o: usize) -> &[[u8; 3]] {
        let start = p.first as usize + o * p.per as usize;
        &self.tris[start..start + p.per as usize]
    }

    /// The cycles of `case` that get a vertex of their own (cube edges, a bit each).
    #[inline]
    pub(super) fn centres(&self, case: usize) -> &[u16] {
        &self.centres[self.centre_start[case] as usize..self.centre_start[case + 1] as usize]
    }
}

/// Position of cube corner `c` in the unit cube.
pub(super) fn corner_pos(c: usize) -> DVec3 {
    let o = corner(c);
    DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)
}

/// Midpoint of cube edge `k` in the unit cube.
pub(super) fn edge_mid(topo: &CubeTopology, k: usize) -> DVec3 {
    let (c, d) = topo.edges[k];
    corner_pos(c) + 0.5 * corner_pos(1 << d)
}

/// The faces of cube edge `k` (a bit per face; none for a cycle's own vertex).
pub(super) fn edge_faces(topo: &CubeTopology, k: usize) -> u8 {
    if k >= MC_CENTRE as usize {
        return 0;
    }
    let (c, d) = topo.edges[k];
    let (u, w) = ((d + 1) % 3, (d + 2) % 3);
    1 << (2 * u + ((c >> u) & 1)) | 1 << (2 * w + ((c >> w) & 1))
}

/// How little the triangles `tris` (vertex indices into `pos`) fold: the smallest cosine
/// between two of their normals; -2 when one is degenerate.
#[inline]
pub(super) fn flatness(pos: &[Vec3], tris: &[[u32; 3]]) -> f64 {
    if let [t0, t1] = tris {
        // A quadrilateral: one cosine, one square root.
        let normal = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| pos[i as usize].as_dvec3());
            (b - a).cross(c - a)
        };
        let (n0, n1) = (normal(t0), normal(t1));
        let c = n0.dot(n1) / (n0.length_squared() * n1.length_squared()).sqrt();
        return if c.is_finite() { c } else { -2.0 };
    }
    let mut normals = [DVec3::ZERO; MC_OPTIONS_UP_TO - 2];
    for (n, t) in normals.iter_mut().zip(tris) {
        let [a, b, c] = t.map(|i| pos[i as usize].as_dvec3());
        *n = (b - a).cross(c - a);
        let len = n.length();
        if !(len > 0.0) {
            return -2.0;
        }
        *n /= len;
    }
    let normals = &normals[..tris.len()];
    let mut worst = 1.0f64;
    for (i, a) in normals.iter().enumerate() {
        for b in &normals[i + 1..] {
            worst = worst.min(a.dot(*b));
        }
    }
    worst
}

/// The asymptotic decider: whether the centre of a face with corner samples `a, b, c, d`
/// (in cyclic order, `a`, `c` of one sign and `b`, `d` of the other) is inside, by the
/// sign of the bilinear interpolant at its saddle. Symmetric under rotating and
/// reversing the corners, so both cells sharing the face decide alike.
#[inline]
pub(super) fn face_centre_inside(a: f64, b: f64, c: f64, d: f64) -> bool {
    let den = a + c - b - d;
    let saddle = if den != 0.0 { (a * c - b * d) / den } else { 0.25 * (a + b + c + d) };
    saddle < 0.0
}

pub(super) fn marching_cubes(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> (TriangleMesh, bool) {
    let signs = Signs::new(grid);
    let (cross, mut positions) =
        Crossings::new(grid, &signs, 3, |p0, v0, p1, v1| crossing_point(f, p0, v0, p1, v1).as_vec3());
    let table = mc_table();
    let topo = CubeTopology::new();
    let n = grid.n;
    let corner_offsets = grid.corner_offsets();
    // Cycle vertices get indices from `CYCLE_VERTEX` up in their slab until the end.
    const CYCLE_VERTEX: u32 = 1 << 31;
    assert!(positions.len() < CYCLE_VERTEX as usize, "too many vertices");
    let per_slab: Vec<(Vec<[u32; 3]>, Vec<Vec3>)> = (0..n[2] - 1)
        .into_par_iter()
        .map(|z| {
            // About two triangles per vertex.
            let mut out = Vec::with_capacity(2 * cross.in_slice(z) + 16);
            let mut extra = Vec::new();
            let mut scratch = [[0u32; 3]; MC_OPTIONS_UP_TO - 2];
            signs.active_cells(z, |x, y, config| {
                let mut ids = [0u32; 12 + 4];
                let mut m = table.crossing[config as usize];
                while m != 0 {
                    let k = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let (c, d) = topo.edges[k];
                    ids[k] = cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d);
                }
                let values = || {
                    let i = grid.idx(x, y, z);
                    corner_offsets.map(|o| grid.values[i + o])
                };
                let case = table.case(&topo, config, values);
                for (j, &cycle) in table.centres(case).iter().enumerate() {
                    let mut sum = DVec3::ZERO;
                    let mut m = cycle;
                    while m != 0 {
                        sum += positions[ids[m.trailing_zeros() as usize] as usize].as_dvec3();
                        m &= m - 1;
                    }
                    ids[MC_CENTRE as usize + j] = CYCLE_VERTEX + extra.len() as u32;
                    extra.push((sum / cycle.count_ones() as f64).as_vec3());
                }
                for &p in table.polygons(case) {
                    let mut best = 0;
                    if p.options > 1 {
                        let mut top = f64::NEG_INFINITY;
                        let tris = &mut scratch[..p.per as usize];
                        for o in 0..p.options as usize {
                            for (t, e) in tris.iter_mut().zip(table.option(p, o)) {
                                *t = e.map(|k| ids[k as usize]);
                            }
                            let s = flatness(&positions, tris);
                            if s > top {
                                (top, best) = (s, o);
                            }
                        }
                    }
                    out.extend(table.option(p, best).iter().map(|t| t.map(|k| ids[k as usize])));
                }
            });
            (out, extra)
        })
        .collect();
    let mut next = positions.len() as u32;
    let mut parts = Vec::with_capacity(per_slab.len());
    let cycle_vertices = per_slab.iter().any(|(_, e)| !e.is_empty());
    for (mut tris, extra) in per_slab {
        if !extra.is_empty() {
            for t in &mut tris {
                t.iter_mut().filter(|i| **i >= CYCLE_VERTEX).for_each(|i| *i = *i - CYCLE_VERTEX + next);
            }
            next += extra.len() as u32;
            positions.extend(extra);
        }
        parts.push(tris);
    }
    (TriangleMesh { positions, triangles: concat(parts), normals: None }, !cycle_vertices)
}

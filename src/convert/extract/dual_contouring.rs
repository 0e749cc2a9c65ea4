//! Dual contouring: one QEF-placed vertex per surface component of a sign-changing cell
//! ([`CubeTopology`] splits a cell's crossings into components), quads across
//! sign-changing edges split along the diagonal closer to the surface.

use super::*;

/// How far (in cells) a dual contouring vertex may leave its cell.
pub(super) const DC_REACH: f64 = 0.5;

/// Dual contouring moves the QEF's vertex of a cell without a corner (rank below 3) this
/// fraction of `f` at the vertex along the crossings' mean normal. On a curved sheet the
/// QEF's minimiser lies on the crossings' tangent planes, so outside a convex surface
/// (inside a concave one) by about the largest sag of the facets between such vertices;
/// halfway back the facets straddle the surface instead of lying wholly on one side. On
/// flat faces and straight creases `f` is 0 there and nothing moves.
pub(super) const SMOOTH_PULL: f64 = 0.5;

/// The cube's 12 edges and 6 faces, for splitting a cell's surface into components.
pub(super) struct CubeTopology {
    /// Edge `k` as (lower corner, axis); `k = 4 * axis + bit_u + 2 * bit_w` where
    /// `u = (axis + 1) % 3`, `w = (axis + 2) % 3` and the bits are the corner's offsets.
    pub(super) edges: [(usize, usize); 12],
    /// Per face: its corners in cyclic order and the edges between consecutive corners
    /// (`edges[i]` joins `corners[i]` and `corners[(i + 1) % 4]`).
    pub(super) faces: [([usize; 4], [usize; 4]); 6],
}

impl CubeTopology {
    pub(super) fn new() -> Self {
        let edges: [(usize, usize); 12] = std::array::from_fn(|k| {
            let d = k / 4;
            let (u, w) = ((d + 1) % 3, (d + 2) % 3);
            (((k & 1) << u) | (((k >> 1) & 1) << w), d)
        });
        let faces = std::array::from_fn(|fi| {
            let (a, side) = (fi / 2, fi % 2);
            let (u, w) = ((a + 1) % 3, (a + 2) % 3);
            let corners: [usize; 4] =
                [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(bu, bw)| (side << a) | (bu << u) | (bw << w));
            let face_edges = std::array::from_fn(|i| {
                let (c0, c1) = (corners[i], corners[(i + 1) % 4]);
                let (lo, d) = (c0 & c1, (c0 ^ c1).trailing_zeros() as usize);
                edges.iter().position(|&e| e == (lo, d)).expect("face edge is a cube edge")
            });
            (corners, face_edges)
        });
        CubeTopology { edges, faces }
    }

    /// Labels the cell's sign-changing edges by surface component (0, 1, ...; `u8::MAX`
    /// for edges without a crossing) and returns the number of components. Crossings on a
    /// face are paired; on a face with four crossings the pairing follows the sign of the
    /// bilinear interpolant's saddle (the asymptotic decider), which both cells sharing
    /// the face agree on.
    ///
    /// Faces whose bit is set in `flip` take the other pairing. Also returns a bit per face
    /// with four crossings whose two pairs ended up in the same component.
    pub(super) fn components(&self, values: &[f32; 8], crossing: u16, flip: u8) -> ([u8; 12], u8, u8) {
        let mut parent: [u8; 12] = std::array::from_fn(|k| k as u8);
        fn find(p: &mut [u8; 12], mut k: u8) -> u8 {
            while p[k as usize] != k {
                p[k as usize] = p[p[k as usize] as usize];
                k = p[k as usize];
            }
            k
        }
        let union = |p: &mut [u8; 12], a: usize, b: usize| {
            let (ra, rb) = (find(p, a as u8), find(p, b as u8));
            p[ra as usize] = rb;
        };
        let mut ambiguous = [None; 6];
        for (fi, (corners, fe)) in self.faces.iter().enumerate() {
            let (mut on, mut len) = ([0usize; 4], 0);
            for (i, &e) in fe.iter().enumerate() {
                if crossing & (1 << e) != 0 {
                    on[len] = i;
                    len += 1;
                }
            }
            match len {
                2 => union(&mut parent, fe[on[0]], fe[on[1]]),
                4 => {
                    let [a, b, c, d] = corners.map(|k| values[k] as f64);
                    let den = a + c - b - d;
                    let saddle = if den != 0.0 { (a * c - b * d) / den } else { 0.25 * (a + b + c + d) };
                    // Corner i is cut off by the segment joining edges i - 1 and i. Cut off
                    // the corners on the side the saddle is not on.
                    let centre_inside = saddle < 0.0;
                    let first_inside = a < 0.0;
                    // Cut off corners 0 and 2 when they are the lone side, else 1 and 3.
                    let cut_even = (first_inside != centre_inside) != (flip & (1 << fi) != 0);
                    let s = if cut_even { 0 } else { 1 };
                    union(&mut parent, fe[(s + 3) % 4], fe[s]);
                    union(&mut parent, fe[s + 1], fe[s + 2]);
                    ambiguous[fi] = Some((fe[s], fe[s + 1]));
                }
                _ => {}
            }
        }
        let mut merged = 0u8;
        for (fi, a) in ambiguous.iter().enumerate() {
            if let Some((e0, e1)) = *a
                && find(&mut parent, e0 as u8) == find(&mut parent, e1 as u8)
            {
                merged |= 1 << fi;
            }
        }
        let mut labels = [u8::MAX; 12];
        let mut root_label = [u8::MAX; 12];
        let mut count = 0u8;
        for (k, label) in labels.iter_mut().enumerate() {
            if crossing & (1 << k) != 0 {
                let r = find(&mut parent, k as u8) as usize;
                if root_label[r] == u8::MAX {
                    root_label[r] = count;
                    count += 1;
                }
                *label = root_label[r];
            }
        }
        (labels, count, merged)
    }
}

/// The mesh, and whether every active cell got exactly one vertex.
pub(super) fn dual_contouring(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> TriangleMesh {
    let signs = Signs::new(grid);
    let eps = 0.01 * grid.h;
    let (cross, crossings) = Crossings::new(grid, &signs, 3, |p0, v0, p1, v1| {
        let p = crossing_point(f, p0, v0, p1, v1);
        (p, gradient(f, p, eps))
    });
    let n = grid.n;
    let nc = [n[0] - 1, n[1] - 1, n[2] - 1];
    let cidx = |x: usize, y: usize, z: usize| x + nc[0] * (y + nc[1] * z);
    let cslice = nc[0] * nc[1];
    let corner_offsets = grid.corner_offsets();
    let topo = CubeTopology::new();
    // A cell's corner samples and which of its 12 edges change sign.
    let config = |i0: usize| -> ([f32; 8], u16) {
        let values = corner_offsets.map(|o| grid.values[i0 + o]);
        let mut crossing = 0u16;
        for (k, &(c, d)) in topo.edges.iter().enumerate() {
            if (values[c] < 0.0) != (values[c | 1 << d] < 0.0) {
                crossing |= 1 << k;
            }
        }
        (values, crossing)
    };
    // Per cell: index of its first vertex and its edges' component labels (2 bits each).
    let mut cell_vertex = vec![u32::MAX; nc[0] * nc[1] * nc[2]];
    let mut cell_labels = vec![0u32; cell_vertex.len()];
    let per_slab: Vec<(Vec<DVec3>, usize)> = cell_vertex
        .par_chunks_mut(cslice)
        .zip(cell_labels.par_chunks_mut(cslice))
        .enumerate()
        .map(|(z, (cv, cl))| {
            let mut verts = Vec::new();
            let mut cells = 0;
            signs.active_cells(z, |x, y, _| {
                cells += 1;
                let i0 = grid.idx(x, y, z);
                let (values, crossing) = config(i0);
                let (mut labels, mut count, merged) = topo.components(&values, crossing, 0);
                if merged != 0 {
                    // An ambiguous face whose two sheets this cell joins into one
                    // component: if the neighbour across it joins them too, the dual edge
                    // between the two cells would be used four times. Both cells then
                    // flip that face's pairing (each decides from the default pairings of
                    // both, so they agree), which splits the components.
                    let mut flip = 0u8;
                    for fi in (0..6).filter(|fi| merged & (1 << fi) != 0) {
                        let stride = [1, n[0], n[0] * n[1]][fi / 2];
                        let nb = if fi % 2 == 1 { i0 + stride } else { i0 - stride };
                        let (nv, nc) = config(nb);
                        if topo.components(&nv, nc, 0).2 & (1 << (fi ^ 1)) != 0 {
                            flip |= 1 << fi;
                        }
                    }
                    if flip != 0 {
                        (labels, count, _) = topo.components(&values, crossing, flip);
                    }
                }
                let mut qefs = [Qef::default(), Qef::default(), Qef::default(), Qef::default()];
                let mut packed = 0u32;
                for (k, &(c, d)) in topo.edges.iter().enumerate() {
                    if labels[k] != u8::MAX {
                        let v = cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d) as usize;
                        let (p, nrm) = crossings[v];
                        qefs[labels[k] as usize].add(p, nrm);
                        packed |= (labels[k] as u32) << (2 * k);
                    }
                }
                let lo = grid.pos(x, y, z);
                let margin = DVec3::splat(EDGE_MARGIN * grid.h);
                cv[x + nc[0] * y] = verts.len() as u32;
                cl[x + nc[0] * y] = packed;
                for q in &qefs[..count as usize] {
                    let (mut v, rank) = q.solve();
                    if rank < 3 {
                        // Curved sheet or crease: halfway to the surface along the mean
                        // normal (see SMOOTH_PULL).
                        let d = f(v);
                        if d.is_finite() {
                            v -= q.normals.normalize_or_zero() * (SMOOTH_PULL * d);
                        }
                    }
                    let reach = DVec3::splat(DC_REACH * grid.h);
                    let (vlo, vhi) = (lo - reach + margin, lo + DVec3::splat(grid.h) + reach - margin);
                    if v.cmplt(vlo).any() || v.cmpgt(vhi).any() {
                        // Far outside the cell (a sharp feature through cells without a
                        // sign change): the best QEF point within reach instead of the
                        // nearest one, which leaves a crease line.
                        v = q.solve_in_box(v, vlo, vhi);
                    }
                    verts.push(v.clamp(vlo, vhi));
                }
            });
            (verts, cells)
        })
        .collect();
    drop(crossings);
    let mut offsets = Vec::with_capacity(per_slab.len());
    let mut total = 0usize;
    let mut cells = 0usize;
    for (v, c) in &per_slab {
        offsets.push(total as u32);
        total += v.len();
        cells += c;
    }
    assert!(total < u32::MAX as usize, "too many vertices for u32 indices");
    cell_vertex.par_chunks_mut(cslice).zip(offsets.par_iter()).for_each(|(cv, &off)| {
        cv.iter_mut().filter(|v| **v != u32::MAX).for_each(|v| *v += off);
    });
    let positions: Vec<Vec3> = per_slab.into_iter().flat_map(|(v, _)| v).map(|p| p.as_vec3()).collect();

    // A quad across every sign-changing cube edge, over the four cells around it.
    let per_slice: Vec<Vec<[u32; 3]>> = (0..n[2])
        .into_par_iter()
        .map(|z| {
            let mut out = Vec::with_capacity(2 * cross.in_slice(z));
            for y in 0..n[1] {
                for d in 0..3 {
                    let row = &cross.bits[((y + n[1] * z) * 3 + d) * cross.words..][..cross.words];
                    for (w, &word) in row.iter().enumerate() {
                        let mut m = word;
                        while m != 0 {
                            let x = 64 * w + m.trailing_zeros() as usize;
                            m &= m - 1;
                            let p = [x, y, z];
                            // Cells around the edge, counter-clockwise about +d; in each,
                            // the edge's local index is 4 d + (1 - du) + 2 (1 - dw). Edges
                            // on the grid's faces never change sign, so all four exist.
                            let (u, w) = ((d + 1) % 3, (d + 2) % 3);
                            let cell = |du: usize, dw: usize| {
                                let mut c = p;
                                c[u] -= 1 - du;
                                c[w] -= 1 - dw;
                                let ci = cidx(c[0], c[1], c[2]);
                                let k = 4 * d + (1 - du) + 2 * (1 - dw);
                                debug_assert!(cell_vertex[ci] != u32::MAX);
                                cell_vertex[ci] + ((cell_labels[ci] >> (2 * k)) & 3)
                            };
                            let mut q = [cell(0, 0), cell(1, 0), cell(1, 1), cell(0, 1)];
                            let mut axis = DVec3::ZERO;
                            axis[d] = 1.0;
                            if !grid.inside(grid.idx(x, y, z)) {
                                q.reverse();
                                axis = -axis;
                            }
                            out.extend(split_quad(f, &positions, q, axis, 1e-4 * grid.h));
                        }
                    }
                }
            }
            out
        })
        .collect();
    TriangleMesh { positions, triangles: concat(per_slice), normals: None }
}

/// Splits the quad `q` (counter-clockwise about `axis`, the outward direction) into two
/// triangles: along a diagonal whose triangles face outwards (never a degenerate triangle
/// when the other diagonal avoids one), of those the one whose midpoint is closer to the
/// surface (`|f|` smaller by more than `tol`), else the one that folds least.
pub(super) fn split_quad(
    f: &impl Fn(DVec3) -> f64,
    pos: &[Vec3],
    q: [u32; 4],
    axis: DVec3,
    tol: f64,
) -> [[u32; 3]; 2] {
    let options = [[[q[0], q[1], q[2]], [q[0], q[2], q[3]]], [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]];
    let score = |tris: &[[u32; 3]; 2]| -> (u8, f64) {
        let mut normals = [DVec3::ZERO; 2];
        let mut facing = 0u8;
        for (k, t) in tris.iter().enumerate() {
            let [a, b, c] = t.map(|i| pos[i as usize]);
            if is_degenerate(a, b, c) {
                return (0, f64::NEG_INFINITY);
            }
            let [a, b, c] = [a, b, c].map(|v| v.as_dvec3());
            normals[k] = (b - a).cross(c - a).normalize_or_zero();
            facing += (normals[k].dot(axis) > 0.0) as u8;
        }
        (1 + facing, normals[0].dot(normals[1]))
    };
    let (s0, s1) = (score(&options[0]), score(&options[1]));
    if s0.0 != s1.0 {
        return if s1.0 > s0.0 { options[1] } else { options[0] };
    }
    let mid = |a: u32, b: u32| f(0.5 * (pos[a as usize].as_dvec3() + pos[b as usize].as_dvec3())).abs();
    let (m0, m1) = (mid(q[0], q[2]), mid(q[1], q[3]));
    if m1 + tol < m0 {
        options[1]
    } else if m0 + tol < m1 {
        options[0]
    } else if s1.1 > s0.1 {
        options[1]
    } else {
        options[0]
    }
}

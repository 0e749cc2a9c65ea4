//! Marching tetrahedra: every cube split into six tetrahedra around its main diagonal
//! (the same split in every cell), each triangulated on its own from a generated table.

use super::*;

/// Cube corner `c` (0..8) offset: bit 0 = x, bit 1 = y, bit 2 = z.
#[inline]
pub(super) fn corner(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// The six tetrahedra around the diagonal 0-7: corners 0, e_i, e_i + e_j, 7.
pub(super) const TETS: [[usize; 4]; 6] =
    [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];

/// A tet edge as (cube corner of its lower end, direction index into [`DIRS`]).
pub(super) type TetEdge = (u8, u8);

/// Per tetrahedron and inside mask (bit k = tet corner k inside): triangles as tet edges.
pub(super) type TetTable = [[Vec<[TetEdge; 3]>; 16]; 6];

pub(super) fn tet_table() -> TetTable {
    let pos = |c: usize| {
        let o = corner(c);
        DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)
    };
    std::array::from_fn(|t| {
        let tet = TETS[t];
        std::array::from_fn(|m| {
            // Edge between tet corners a and b (either order): lower corner, direction.
            let edge = |a: usize, b: usize| -> (TetEdge, DVec3) {
                let (ca, cb) = (tet[a.min(b)], tet[a.max(b)]);
                let (oa, ob) = (corner(ca), corner(cb));
                let d = [ob[0] - oa[0], ob[1] - oa[1], ob[2] - oa[2]];
                let dir = DIRS.iter().position(|&x| x == d).expect("tet edge along a grid direction");
                ((ca as u8, dir as u8), 0.5 * (pos(ca) + pos(cb)))
            };
            // Orients the triangle so that its normal points away from `inside_ref` (a
            // point never coplanar with it for any crossing parameter in (0, 1)).
            let tri = |e: [(usize, usize); 3], reference: usize, ref_inside: bool| -> [TetEdge; 3] {
                let [(k0, p0), (k1, p1), (k2, p2)] = e.map(|(a, b)| edge(a, b));
                let r = pos(tet[reference]);
                let s = (p1 - p0).cross(p2 - p0).dot(r - p0);
                // Normal towards an outside reference, away from an inside one.
                if (s < 0.0) == ref_inside { [k0, k1, k2] } else { [k0, k2, k1] }
            };
            let ins: Vec<usize> = (0..4).filter(|k| m & (1 << k) != 0).collect();
            let out: Vec<usize> = (0..4).filter(|k| m & (1 << k) == 0).collect();
            match ins.len() {
                1 => {
                    let a = ins[0];
                    vec![tri([(a, out[0]), (a, out[1]), (a, out[2])], a, true)]
                }
                3 => {
                    let d = out[0];
                    vec![tri([(d, ins[0]), (d, ins[1]), (d, ins[2])], d, false)]
                }
                2 => {
                    let (a, b, c, d) = (ins[0], ins[1], out[0], out[1]);
                    // Quad ac, ad, bd, bc split along ac-bd.
                    vec![tri([(a, c), (a, d), (b, d)], a, true), tri([(a, c), (b, d), (b, c)], b, true)]
                }
                _ => Vec::new(),
            }
        })
    })
}

/// Per cube inside mask (bit c = corner c inside): the triangles of all six tetrahedra,
/// as tet edges, in `tris[start[m]..start[m + 1]]`.
pub(super) struct CubeTable {
    pub(super) start: [u16; 257],
    pub(super) tris: Vec<[TetEdge; 3]>,
}

pub(super) fn cube_table() -> CubeTable {
    let table = tet_table();
    let mut start = [0u16; 257];
    let mut tris = Vec::new();
    for (cm, s) in start.iter_mut().take(256).enumerate() {
        *s = tris.len() as u16;
        for (t, tet) in TETS.iter().enumerate() {
            let m = tet.iter().enumerate().fold(0, |m, (k, &c)| m | (((cm >> c) & 1) << k));
            tris.extend_from_slice(&table[t][m]);
        }
    }
    start[256] = tris.len() as u16;
    CubeTable { start, tris }
}

pub(super) fn marching_tetrahedra(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> TriangleMesh {
    let signs = Signs::new(grid);
    let (cross, positions) = Crossings::new(grid, &signs, DIRS.len(), |p0, v0, p1, v1| {
        crossing_point(f, p0, v0, p1, v1).as_vec3()
    });
    let table = cube_table();
    let n = grid.n;
    let per_slab: Vec<Vec<[u32; 3]>> = (0..n[2] - 1)
        .into_par_iter()
        .map(|z| {
            // About two triangles per vertex.
            let mut out = Vec::with_capacity(2 * cross.in_slice(z) + 16);
            signs.active_cells(z, |x, y, cm| {
                let (a, b) = (table.start[cm as usize] as usize, table.start[cm as usize + 1] as usize);
                for tri in &table.tris[a..b] {
                    out.push(tri.map(|(c, d)| {
                        let c = c as usize;
                        cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d as usize)
                    }));
                }
            });
            out
        })
        .collect();
    TriangleMesh { positions, triangles: concat(per_slab), normals: None }
}

/// The vectors of `parts` one after another.
pub(super) fn concat<T: Copy + Send + Sync>(parts: Vec<Vec<T>>) -> Vec<T> {
    let total = parts.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(total);
    for p in &parts {
        out.extend_from_slice(p);
    }
    out
}

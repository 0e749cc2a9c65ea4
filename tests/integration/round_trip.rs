//! Round trip SDF -> mesh -> grid (issue 4): an analytic SDF extracted into a mesh, the
//! mesh sampled back into a grid, stays close to the SDF: near the surface the grid's
//! samples are within a fraction of the extraction's cell size of the exact distance, and
//! every sample farther than a cell from the surface has the right sign.

use glam::{DVec3, Vec3};
use sdfmesh::convert::extract::{ExtractMethod, Field, extract};
use sdfmesh::convert::mesh_to_grid::sample_mesh;
use sdfmesh::geometry::Aabb;

fn cube(h: f32) -> Aabb {
    Aabb::new(Vec3::splat(-h).into(), Vec3::splat(h).into())
}

/// Extracts `f` at `res` cells over `[-1.2, 1.2]^3`, samples the mesh at 32 cells, and
/// returns (largest error within `band` of the surface, wrong signs beyond one cell).
fn round_trip(
    f: &(impl Fn(DVec3) -> f64 + Sync),
    res: u32,
    method: ExtractMethod,
    band: f64,
) -> (f64, usize) {
    let mesh = extract(f, Field::Arbitrary, &cube(1.2), res, method);
    assert!(mesh.is_closed(), "{method:?} at {res}: the extracted mesh is closed");
    let grid = sample_mesh(&mesh, 32, 2).unwrap();
    let h = 2.4 / res as f64;
    let (mut worst, mut wrong) = (0.0f64, 0usize);
    for k in 0..grid.dims.z {
        for j in 0..grid.dims.y {
            for i in 0..grid.dims.x {
                let p = grid.position(i, j, k).as_dvec3();
                let exact = f(p);
                let got = grid.get(i, j, k) as f64;
                if exact.abs() < band {
                    worst = worst.max((got - exact).abs());
                }
                if exact.abs() > h && got.signum() != exact.signum() {
                    wrong += 1;
                }
            }
        }
    }
    (worst, wrong)
}

#[test]
fn sphere_round_trip_error_shrinks_with_resolution() {
    let sphere = |p: DVec3| p.length() - 0.9;
    let mut last = f64::MAX;
    for res in [16, 32, 64] {
        let h = 2.4 / res as f64;
        let (worst, wrong) = round_trip(&sphere, res, ExtractMethod::MarchingCubes, 0.3);
        eprintln!("sphere res {res}: max error {worst:.2e} ({:.3} cells), {wrong} wrong signs", worst / h);
        // Marching cubes places vertices on the surface (refined crossings), so the
        // chord error is O(h^2): well under a tenth of a cell at these sizes.
        assert!(worst < 0.1 * h, "res {res}: error {worst} vs cell {h}");
        assert!(worst < last, "res {res}: error {worst} did not shrink from {last}");
        assert_eq!(wrong, 0, "res {res}");
        last = worst;
    }
}

#[test]
fn box_round_trip_keeps_sharp_edges_with_dual_contouring() {
    let half = DVec3::new(0.8, 0.5, 0.6);
    let boxf = move |p: DVec3| {
        let q = p.abs() - half;
        q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
    };
    let res = 24;
    let h = 2.4 / res as f64;
    let (dc, wrong_dc) = round_trip(&boxf, res, ExtractMethod::DualContouring, 0.3);
    let (mt, wrong_mt) = round_trip(&boxf, res, ExtractMethod::MarchingTetrahedra, 0.3);
    let (mc, wrong_mc) = round_trip(&boxf, res, ExtractMethod::MarchingCubes, 0.3);
    eprintln!(
        "box res {res}: dual contouring {dc:.2e}, marching tetrahedra {mt:.2e}, marching cubes {mc:.2e}, cell {h:.3}"
    );
    assert_eq!((wrong_dc, wrong_mt, wrong_mc), (0, 0, 0));
    // Dual contouring reproduces the edges and corners; marching tetrahedra and cubes cut
    // them off (by up to about a cell's diagonal; marching cubes, without the face and
    // body diagonals' vertices, cuts deeper).
    assert!(dc < 0.05 * h, "dual contouring: {dc} vs cell {h}");
    assert!(mt > 2.0 * dc && mt < 1.0 * h, "marching tetrahedra: {mt}, dual: {dc}, cell {h}");
    assert!(mc > 2.0 * dc && mc < 3f64.sqrt() * h, "marching cubes: {mc}, dual: {dc}, cell {h}");
}

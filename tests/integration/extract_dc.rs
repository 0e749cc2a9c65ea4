//! Dual contouring on curved surfaces: facets straddle the surface (vertices outside a
//! convex surface, facet interiors inside), and the mesh lies closer to the surface than
//! marching cubes' at the same resolution, measured densely over each triangle's area.

use glam::{DVec3, Vec3A};
use sdfmesh::convert::extract::{ExtractMethod, Field, extract};
use sdfmesh::geometry::Aabb;
use sdfmesh::mesh::TriangleMesh;

/// A torus (major radius 0.6, minor 0.25) tilted about x: an exact SDF, so `|f|` is the
/// distance to the surface; convex and saddle-shaped parts.
fn torus(p: DVec3) -> f64 {
    let (s, c) = 0.5f64.sin_cos();
    let q = DVec3::new(p.x, c * p.y - s * p.z, s * p.y + c * p.z);
    DVec3::new(DVec3::new(q.x, 0.0, q.z).length() - 0.6, q.y, 0.0).length() - 0.25
}

/// Area-weighted mean of `|f|` over each triangle (the centroids of its 36 sub-triangles
/// of a 6 x 6 subdivision, upward and downward), and the largest value seen.
fn area_mean_distance(m: &TriangleMesh, f: impl Fn(DVec3) -> f64) -> (f64, f64) {
    let (mut sum, mut area_sum, mut max) = (0.0, 0.0, 0.0f64);
    let n = 6;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
        let area = 0.5 * (b - a).cross(c - a).length();
        let (mut s, mut k) = (0.0, 0);
        for i in 0..n {
            for j in 0..n - i {
                let mut pts = vec![(i as f64 + 1.0 / 3.0, j as f64 + 1.0 / 3.0)];
                if i + j + 1 < n {
                    pts.push((i as f64 + 2.0 / 3.0, j as f64 + 2.0 / 3.0));
                }
                for (u, v) in pts {
                    let d = f(a + (b - a) * (u / n as f64) + (c - a) * (v / n as f64)).abs();
                    s += d;
                    max = max.max(d);
                    k += 1;
                }
            }
        }
        sum += area * s / k as f64;
        area_sum += area;
    }
    (sum / area_sum, max)
}

#[test]
fn dual_contouring_is_closer_than_marching_cubes_on_curved_surfaces() {
    let bounds = Aabb::new(Vec3A::new(-0.9, -0.9, -0.9), Vec3A::new(0.9, 0.9, 0.9));
    for res in [16u32, 24, 32] {
        let dc = extract(&torus, Field::Arbitrary, &bounds, res, ExtractMethod::DualContouring);
        let mc = extract(&torus, Field::Arbitrary, &bounds, res, ExtractMethod::MarchingCubes);
        assert!(dc.is_closed() && mc.is_closed(), "res {res}");
        let (dm, dmax) = area_mean_distance(&dc, torus);
        let (mm, mmax) = area_mean_distance(&mc, torus);
        let tris = (dc.triangles.len() as f64 / mc.triangles.len() as f64 - 1.0).abs();
        println!(
            "res {res}: DC mean {dm:.3e} max {dmax:.3e}, MC mean {mm:.3e} max {mmax:.3e}, ratio {:.3} / {:.3}",
            dm / mm,
            dmax / mmax
        );
        // About the same number of triangles, so a fair comparison.
        assert!(tris < 0.05, "res {res}: triangle counts differ by {tris}");
        assert!(dm < 0.45 * mm, "res {res}: DC mean {dm} vs MC {mm}");
        assert!(dmax < 0.8 * mmax, "res {res}: DC max {dmax} vs MC {mmax}");
    }
}

/// On a sphere the facets straddle the surface: vertices outside, most facet centroids
/// inside, and the vertices are not on the QEF's tangent planes (about the facets' largest
/// sag outside) but about halfway between those and the surface.
#[test]
fn dual_contouring_facets_straddle_a_sphere() {
    let f = |p: DVec3| p.length() - 0.7;
    let bounds = Aabb::new(Vec3A::splat(-0.8), Vec3A::splat(0.8));
    let m = extract(&f, Field::Arbitrary, &bounds, 20, ExtractMethod::DualContouring);
    let outside = m.positions.iter().filter(|p| f(p.as_dvec3()) > 0.0).count();
    let inside_centroids = m
        .triangles
        .iter()
        .filter(|t| f(t.map(|i| m.positions[i as usize].as_dvec3()).iter().sum::<DVec3>() / 3.0) < 0.0)
        .count();
    let vmean = m.positions.iter().map(|p| f(p.as_dvec3())).sum::<f64>() / m.positions.len() as f64;
    let (dm, _) = area_mean_distance(&m, f);
    println!(
        "{} of {} vertices outside, {} of {} centroids inside, vertex mean f {vmean:.3e}, area mean |f| {dm:.3e}",
        outside,
        m.positions.len(),
        inside_centroids,
        m.triangles.len()
    );
    assert!(outside as f64 > 0.9 * m.positions.len() as f64);
    assert!(inside_centroids as f64 > 0.5 * m.triangles.len() as f64);
    // Vertices outside by less than three times the mesh's mean distance.
    assert!(vmean > 0.0 && vmean < 3.0 * dm, "vertex offset {vmean} vs mean distance {dm}");
}

/// Thin wedges: the rim of a sphere with a spherical bite (a 61.5° edge) and the edge of a
/// lens pass between the grid points of cells they cross. Vertices reach out of their cells
/// and slide along the crease, so every vertex stays within 0.15 cells of the surface
/// (clamped into their cells some were 0.3 cells inside); closed and manifold.
#[test]
fn thin_wedges_keep_their_vertices_on_the_surface() {
    let sphere = |p: DVec3, c: DVec3, r: f64| (p - c).length() - r;
    let bite = move |p: DVec3| sphere(p, DVec3::ZERO, 1.0).max(-sphere(p, DVec3::new(0.3, 0.3, -0.8), 0.7));
    let lens = move |p: DVec3| sphere(p, DVec3::X * -0.5, 1.0).max(sphere(p, DVec3::X * 0.5, 1.0));
    let bounds = Aabb::new(Vec3A::splat(-1.05), Vec3A::splat(1.05));
    let fields: [(&str, &(dyn Fn(DVec3) -> f64 + Sync)); 2] = [("bite", &bite), ("lens", &lens)];
    for (name, f) in fields {
        for res in [32u32, 64, 128] {
            let h = 2.1 / res as f64;
            let m = extract(&f, Field::DistanceBound, &bounds, res, ExtractMethod::DualContouring);
            let worst = m.positions.iter().map(|p| f(p.as_dvec3()).abs()).fold(0.0, f64::max) / h;
            println!("{name} res {res}: {} triangles, worst vertex {worst:.3} cells", m.triangles.len());
            assert!(m.is_closed(), "{name} res {res}: {} boundary edges", m.boundary_edge_count());
            assert!(worst < 0.15, "{name} res {res}: a vertex {worst} cells off the surface");
        }
    }
}

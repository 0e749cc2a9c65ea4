//! Error metrics between a rendering and its reference: image error (RMSE, PSNR, SSIM, and
//! FLIP, an estimate of the error a viewer sees), silhouette disagreement (pixels where one
//! representation hits a surface and the other does not), geometric error in pixels (per
//! pixel, how far apart the two surfaces are in units of the pixel footprint at that depth)
//! and geometric error between two surfaces (symmetric Chamfer and Hausdorff distances over
//! points sampled on each surface, measured with the other surface's exact distance query,
//! [`crate::geometry::Geometry::surface_distance`]). [`QualityLevel`] turns the pixel, the
//! silhouette and the FLIP error into one grade, `quality_px`.
//!
//! Surfaces are sampled where the camera sees them: the first hits of the camera's primary
//! rays ([`probe`]). This is representation-agnostic (every geometry answers rays), covers
//! unbounded surfaces out to where the camera looks, and weights error by what is visible.

use glam::DVec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::geometry::{Geometry, RayStats};
use crate::scene::Camera;
use crate::scene::camera::RayGenerator;

/// Mean squared error of two equally sized RGB images on a [0, 1] scale, over all
/// channels.
///
/// # Panics
/// When the sizes differ.
pub fn mse(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions(), "images of different sizes");
    let n = a.as_raw().len().max(1) as f64;
    let sum: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| {
            let d = (x as f64 - y as f64) / 255.0;
            d * d
        })
        .sum();
    sum / n
}

/// Root mean squared error on a [0, 1] scale.
pub fn rmse(a: &RgbImage, b: &RgbImage) -> f64 {
    mse(a, b).sqrt()
}

/// Peak signal-to-noise ratio in dB for a peak of 1 (`+inf` for identical images).
pub fn psnr_db(a: &RgbImage, b: &RgbImage) -> f64 {
    let m = mse(a, b);
    if m == 0.0 { f64::INFINITY } else { -10.0 * m.log10() }
}

/// Luma (Rec. 601 weights) on a [0, 1] scale, row-major.
fn luma(img: &RgbImage) -> Vec<f64> {
    img.pixels().map(|p| (0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64) / 255.0).collect()
}

/// Structural similarity (Wang et al. 2004) of the images' luma: an 11x11 Gaussian window
/// of sigma 1.5 (truncated at the image border and renormalised), `C1 = (0.01)^2`,
/// `C2 = (0.03)^2` for a dynamic range of 1, averaged over all pixels. 1 for identical
/// images.
///
/// # Panics
/// When the sizes differ.
pub fn ssim(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions(), "images of different sizes");
    let (w, h) = (a.width() as usize, a.height() as usize);
    if w == 0 || h == 0 {
        return 1.0;
    }
    let (x, y) = (luma(a), luma(b));
    const R: isize = 5;
    let kernel: Vec<f64> = (-R..=R).map(|i| (-(i * i) as f64 / (2.0 * 1.5 * 1.5)).exp()).collect();
    // Separable weighted sums of x, y, x^2, y^2, xy: horizontal pass then vertical.
    let fields: [Vec<f64>; 5] = [
        x.clone(),
        y.clone(),
        x.iter().map(|v| v * v).collect(),
        y.iter().map(|v| v * v).collect(),
        x.iter().zip(&y).map(|(a, b)| a * b).collect(),
    ];
    let blur = |f: &[f64]| -> Vec<f64> {
        let mut tmp = vec![0.0; w * h];
        for r in 0..h {
            for c in 0..w {
                let (mut s, mut ws) = (0.0, 0.0);
                for (k, wk) in kernel.iter().enumerate() {
                    let cc = c as isize + k as isize - R;
                    if cc >= 0 && (cc as usize) < w {
                        s += wk * f[r * w + cc as usize];
                        ws += wk;
                    }
                }
                tmp[r * w + c] = s / ws;
            }
        }
        let mut out = vec![0.0; w * h];
        for r in 0..h {
            for c in 0..w {
                let (mut s, mut ws) = (0.0, 0.0);
                for (k, wk) in kernel.iter().enumerate() {
                    let rr = r as isize + k as isize - R;
                    if rr >= 0 && (rr as usize) < h {
                        s += wk * tmp[rr as usize * w + c];
                        ws += wk;
                    }
                }
                out[r * w + c] = s / ws;
            }
        }
        out
    };
    let [mx, my, mxx, myy, mxy] = fields.map(|f| blur(&f));
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let total: f64 = (0..w * h)
        .map(|i| {
            let (ux, uy) = (mx[i], my[i]);
            let vx = (mxx[i] - ux * ux).max(0.0);
            let vy = (myy[i] - uy * uy).max(0.0);
            let cxy = mxy[i] - ux * uy;
            ((2.0 * ux * uy + c1) * (2.0 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
        })
        .sum();
    total / (w * h) as f64
}

/// What the camera's primary rays see of a geometry: per pixel whether a surface is hit,
/// and the hit points.
pub struct Probe {
    /// Per pixel (row-major), whether the primary ray hits a surface.
    pub hits: Vec<bool>,
    /// Hit points of the primary rays that hit, world space, in pixel order (the `i`-th
    /// point belongs to the `i`-th pixel whose `hits` is true).
    pub points: Vec<DVec3>,
}

/// The angle one pixel subtends at the image centre, radians: `2 tan(fov_y / 2) / height`
/// (the same footprint [`crate::plan::Representation::with_pixel_footprint`] gives the
/// marcher). A pixel seen at distance `t` covers about `t * pixel_angle` scene units.
pub fn pixel_angle(camera: &Camera) -> f64 {
    2.0 * ((camera.fov_y_deg as f64).to_radians() * 0.5).tan() / camera.height.max(1) as f64
}

/// Casts one primary ray per pixel of `camera` into `geometry` (closest hits up to
/// `max_distance`).
pub fn probe(camera: &Camera, geometry: &dyn Geometry, max_distance: f32) -> Probe {
    let rays = RayGenerator::new(camera);
    let (w, h) = (camera.width, camera.height);
    let rows: Vec<(Vec<bool>, Vec<DVec3>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut stats = RayStats::default();
            let mut hits = Vec::with_capacity(w as usize);
            let mut points = Vec::new();
            for x in 0..w {
                let hit = geometry.closest_hit(&rays.ray(x, y), 0.0, max_distance, &mut stats);
                hits.push(hit.is_some());
                if let Some(hit) = hit {
                    points.push(hit.point.as_dvec3());
                }
            }
            (hits, points)
        })
        .collect();
    let mut probe = Probe { hits: Vec::with_capacity((w * h) as usize), points: Vec::new() };
    for (hits, points) in rows {
        probe.hits.extend(hits);
        probe.points.extend(points);
    }
    probe
}

/// Percentage of pixels where exactly one of the two probes hits a surface (the silhouettes
/// differ there).
///
/// # Panics
/// When the probes have different pixel counts.
pub fn silhouette_mismatch_pct(a: &Probe, b: &Probe) -> f64 {
    assert_eq!(a.hits.len(), b.hits.len(), "probes of different cameras");
    let n = a.hits.len().max(1) as f64;
    100.0 * a.hits.iter().zip(&b.hits).filter(|(x, y)| x != y).count() as f64 / n
}

/// Geometric error in pixels over the pixels where both a run and its reference hit a
/// surface with the primary ray (see [`pixel_error`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelError {
    /// Mean over those pixels, pixels.
    pub mean: f64,
    /// 95th percentile (nearest rank), pixels.
    pub p95: f64,
    /// Largest, pixels.
    pub max: f64,
    /// Pixels measured (both hit).
    pub pixels: usize,
}

/// Geometric error in pixels: for every pixel where the primary rays of both `candidate`
/// and `reference` hit a surface, the distance between the two surfaces at that pixel over
/// the pixel footprint at the reference hit's depth (`t * pixel_angle`, `t` the distance from
/// `origin`, the camera position). `None` when no pixel is hit by both.
///
/// The distance at a pixel is `max(reference.surface_distance(c), candidate.surface_distance(r))`
/// with `c`, `r` the candidate's and the reference's hit points. Each one-sided term alone
/// misses an error: the first is 0 when the candidate lost a front surface and its ray hits
/// another part of the reference behind it (`c` lies on the reference); the second is 0 when
/// the candidate grew a surface in front of the reference one (`r` lies on the candidate, which
/// still holds it). The maximum is 0 only when each hit lies on the other's surface, and for a
/// surface displaced by `d` along its normal it is `d` (up to the curvature of the surfaces).
/// Both distances are exact or upper bounds ([`Geometry::surface_distance`]).
///
/// # Panics
/// When the probes have different pixel counts.
pub fn pixel_error(
    candidate: &dyn Geometry,
    candidate_probe: &Probe,
    reference: &dyn Geometry,
    reference_probe: &Probe,
    origin: DVec3,
    pixel_angle: f64,
) -> Option<PixelError> {
    assert_eq!(candidate_probe.hits.len(), reference_probe.hits.len(), "probes of different cameras");
    // Pair the hit points of the pixels both hit (points are stored in pixel order).
    let mut pairs = Vec::new();
    let (mut ic, mut ir) = (0, 0);
    for (&hc, &hr) in candidate_probe.hits.iter().zip(&reference_probe.hits) {
        if hc && hr {
            pairs.push((candidate_probe.points[ic], reference_probe.points[ir]));
        }
        ic += hc as usize;
        ir += hr as usize;
    }
    if pairs.is_empty() {
        return None;
    }
    let mut err: Vec<f64> = pairs
        .par_iter()
        .map(|&(c, r)| {
            let d = reference.surface_distance(c).max(candidate.surface_distance(r));
            let footprint = ((r - origin).length() * pixel_angle).max(f64::MIN_POSITIVE);
            d / footprint
        })
        .collect();
    err.sort_by(f64::total_cmp);
    let n = err.len();
    Some(PixelError {
        mean: err.iter().sum::<f64>() / n as f64,
        p95: err[((0.95 * n as f64).ceil() as usize).clamp(1, n) - 1],
        max: err[n - 1],
        pixels: n,
    })
}

/// Mean FLIP error (Andersson et al. 2020, NVIDIA's LDR-FLIP through the `nv-flip` crate) of
/// `test` against `reference`, in [0, 1]: 0 for identical images. Both images are taken as
/// sRGB; the viewing condition is FLIP's default, [`nv_flip::DEFAULT_PIXELS_PER_DEGREE`]
/// (about 67 pixels per degree: a 0.7 m wide 3840-pixel monitor seen from 0.7 m), so a pixel
/// is judged as it would look on a desktop display. 0 for empty images.
///
/// # Panics
/// When the sizes differ.
pub fn flip_mean(test: &RgbImage, reference: &RgbImage) -> f64 {
    assert_eq!(test.dimensions(), reference.dimensions(), "images of different sizes");
    let (w, h) = test.dimensions();
    if w == 0 || h == 0 {
        return 0.0;
    }
    let r = nv_flip::FlipImageRgb8::with_data(w, h, reference.as_raw());
    let t = nv_flip::FlipImageRgb8::with_data(w, h, test.as_raw());
    let map = nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec();
    map.iter().map(|&v| v as f64).sum::<f64>() / map.len() as f64
}

/// One grade of `quality_px`: a run meets it when its 95th-percentile pixel error is at most
/// `px` pixels, at most `max_silhouette_pct` percent of the pixels differ in silhouette, and
/// its mean FLIP is at most `max_flip_mean`. The bounds depend on the image size
/// ([`quality_levels`]); [`QUALITY_LEVELS`] are those at 256 x 256.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QualityLevel {
    /// Largest `px_err_p95`, pixels (the level's name).
    pub px: f64,
    /// Largest `silhouette_mismatch_pct`, percent of the image's pixels.
    pub max_silhouette_pct: f64,
    /// Largest `flip_mean`.
    pub max_flip_mean: f64,
}

/// The quality levels at 256 x 256 pixels, finest first. The silhouette and FLIP bounds were
/// chosen on the bundled scenes at 256x256 pixels with `--res 16,64`: every
/// sphere-traced run at 0.25 px that looks like the reference meets 0.5 px or 1 px (FLIP
/// 0.007-0.047, silhouette <= 0.5%); runs with a visible defect fail every level: grids of
/// `coursework_mirrors` that lost both thin mirrors (silhouette 23.6%), grids of `showcase`
/// with a garbled mirror (FLIP 0.12-0.13), `showcase` sphere traced at 1 px with speckles
/// on edges (FLIP 0.124), a radius-5000 ground sphere tessellated into facets (`thesis_rt`,
/// p95 16-10^4 px). A tolerance of L pixels fattens silhouettes by up to L pixels, so the
/// silhouette bound grows with L. Not caught: a wrong colour on a small part of the image (a
/// CSG part given its parent's material in `thesis_sdf_csg` meshes and grids, FLIP 0.05).
/// Other sizes scale these bounds by [`GATE_TABLE`].
pub const QUALITY_LEVELS: [QualityLevel; 3] = [
    QualityLevel { px: 0.5, max_silhouette_pct: 0.5, max_flip_mean: 0.05 },
    QualityLevel { px: 1.0, max_silhouette_pct: 1.5, max_flip_mean: 0.08 },
    QualityLevel { px: 2.0, max_silhouette_pct: 4.0, max_flip_mean: 0.1 },
];

/// The image sides (square images) the gates are calibrated at.
pub const GATE_SIZES: [u32; 4] = [128, 256, 512, 1024];

/// The silhouette and FLIP bounds per level ([`QUALITY_LEVELS`]' order) and image side
/// ([`GATE_SIZES`]' order), as `(max_silhouette_pct, max_flip_mean)`: the 256 x 256 bounds
/// scaled by how much the same sphere-traced runs' silhouette mismatch and mean FLIP change
/// with the image size (`tools/calibrate-gates`, on 9 scenes of the smooth, CSG and CAD
/// generators with seeds outside the study; reports/bench/gates.txt has the data). An
/// outline off by L pixels is a share of the image that halves when its side doubles, and
/// the measured ratios follow that.
pub const GATE_TABLE: [[(f64, f64); 4]; 3] = GATE_TABLE_VALUES;

/// `GATE_TABLE`'s numbers as tools/calibrate-gates wrote them (reports/bench/gates.csv).
const GATE_TABLE_VALUES: [[(f64, f64); 4]; 3] = [
    [(0.895, 0.0821), (0.5, 0.05), (0.25, 0.0287), (0.129, 0.0162)],
    [(3.004, 0.1298), (1.5, 0.08), (0.773, 0.0469), (0.4, 0.0272)],
    [(7.964, 0.161), (4.0, 0.1), (2.026, 0.0583), (1.033, 0.0341)],
];

/// The quality levels for a `width` x `height` image: [`GATE_TABLE`] interpolated linearly
/// in log(bound) against log(side) (side: the geometric mean of width and height), clamped
/// to the calibrated sides at either end.
pub fn quality_levels(width: u32, height: u32) -> [QualityLevel; 3] {
    let side = ((width.max(1) as f64) * (height.max(1) as f64)).sqrt();
    let ls: Vec<f64> = GATE_SIZES.iter().map(|&s| (s as f64).ln()).collect();
    let x = side.ln().clamp(ls[0], ls[ls.len() - 1]);
    let k = (1..ls.len()).find(|&k| x <= ls[k]).unwrap_or(ls.len() - 1);
    let f = (x - ls[k - 1]) / (ls[k] - ls[k - 1]);
    let lerp = |a: f64, b: f64| {
        if f <= 0.0 {
            a
        } else if f >= 1.0 {
            b
        } else {
            (a.ln() + f * (b.ln() - a.ln())).exp()
        }
    };
    std::array::from_fn(|i| {
        let (a, b) = (GATE_TABLE[i][k - 1], GATE_TABLE[i][k]);
        QualityLevel {
            px: QUALITY_LEVELS[i].px,
            max_silhouette_pct: lerp(a.0, b.0),
            max_flip_mean: lerp(a.1, b.1),
        }
    })
}

impl QualityLevel {
    /// Whether a run with these errors meets this level (`px_err_p95` `None`: no pixel hit by
    /// both, which meets no level).
    pub fn met(&self, px_err_p95: Option<f64>, silhouette_mismatch_pct: f64, flip_mean: f64) -> bool {
        px_err_p95.is_some_and(|p| p <= self.px)
            && silhouette_mismatch_pct <= self.max_silhouette_pct
            && flip_mean <= self.max_flip_mean
    }
}

/// `quality_px`: the finest of the levels of a `width` x `height` image
/// ([`quality_levels`]) that a run meets (its `px`), or `None`.
pub fn quality_px(
    px_err_p95: Option<f64>,
    silhouette_mismatch_pct: f64,
    flip_mean: f64,
    width: u32,
    height: u32,
) -> Option<f64> {
    quality_levels(width, height)
        .iter()
        .find(|l| l.met(px_err_p95, silhouette_mismatch_pct, flip_mean))
        .map(|l| l.px)
}

/// The bounding-box diagonal of the points that lie on bounded objects of `objects` (the
/// scale of relative surface errors), or `None` when no point does. An object is unbounded
/// when its `bounds()` is `None` or when its box's diagonal exceeds 100 times the median
/// diagonal of the objects with bounds (the lower median: with a sphere on a radius-5000
/// ground sphere, the sphere's); a point lies on an
/// object when it is inside the object's box grown by 1e-6 of its diagonal (and by the f32
/// rounding of the point). Infinite planes and ground spheres would otherwise make the scale
/// the distance to the horizon.
pub fn bounded_diagonal(objects: &[Box<dyn Geometry>], points: &[DVec3]) -> Option<f64> {
    let boxes: Vec<(DVec3, DVec3)> =
        objects.iter().filter_map(|o| o.bounds()).map(|b| (b.min.as_dvec3(), b.max.as_dvec3())).collect();
    let mut diagonals: Vec<f64> = boxes.iter().map(|(lo, hi)| (*hi - *lo).length()).collect();
    diagonals.sort_by(f64::total_cmp);
    // The lower median: with two objects, a sphere and a ground, the sphere's.
    let limit = 100.0 * diagonals.get(diagonals.len().saturating_sub(1) / 2).copied().unwrap_or(0.0);
    let bounded: Vec<(DVec3, DVec3)> = boxes
        .into_iter()
        .filter(|(lo, hi)| (*hi - *lo).length() <= limit)
        .map(|(lo, hi)| {
            let pad = 1e-6 * (hi - lo).length() + 1e-6 * lo.abs().max(hi.abs()).max_element();
            (lo - DVec3::splat(pad), hi + DVec3::splat(pad))
        })
        .collect();
    let (lo, hi) = points
        .iter()
        .filter(|p| bounded.iter().any(|(lo, hi)| p.cmpge(*lo).all() && p.cmple(*hi).all()))
        .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    (lo.x <= hi.x).then(|| (hi - lo).length())
}

/// Symmetric distances between two surfaces, in scene units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceDistance {
    /// Mean of the two one-sided mean distances.
    pub chamfer: f64,
    /// Largest distance from a sample of either surface to the other surface.
    pub hausdorff: f64,
    /// Bounding-box diagonal of the reference samples (the scale for relative errors).
    pub diagonal: f64,
}

impl SurfaceDistance {
    /// Chamfer distance relative to the reference's diagonal.
    pub fn chamfer_rel(&self) -> f64 {
        self.chamfer / self.diagonal.max(f64::MIN_POSITIVE)
    }

    /// Hausdorff distance relative to the reference's diagonal.
    pub fn hausdorff_rel(&self) -> f64 {
        self.hausdorff / self.diagonal.max(f64::MIN_POSITIVE)
    }
}

/// Every `k`-th point so that at most `max` remain (a deterministic subsample).
pub fn subsample(points: &[DVec3], max: usize) -> Vec<DVec3> {
    let k = points.len().div_ceil(max.max(1)).max(1);
    points.iter().step_by(k).copied().collect()
}

/// The Chamfer and Hausdorff distances between the surfaces of `candidate` and `reference`
/// from points sampled on each (`candidate_points` on the candidate, `reference_points` on
/// the reference), each measured with the other's exact distance query. `None` when
/// either sample set is empty (then the surfaces cannot be compared where the camera
/// looks).
pub fn surface_distance(
    candidate: &dyn Geometry,
    candidate_points: &[DVec3],
    reference: &dyn Geometry,
    reference_points: &[DVec3],
) -> Option<SurfaceDistance> {
    if candidate_points.is_empty() || reference_points.is_empty() {
        return None;
    }
    let one_sided = |points: &[DVec3], other: &dyn Geometry| -> (f64, f64) {
        let d: Vec<f64> = points.par_iter().map(|&p| other.surface_distance(p)).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (mean, d.iter().copied().fold(0.0, f64::max))
    };
    let (mean_a, max_a) = one_sided(candidate_points, reference);
    let (mean_b, max_b) = one_sided(reference_points, candidate);
    let (lo, hi) = reference_points
        .iter()
        .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    Some(SurfaceDistance {
        chamfer: 0.5 * (mean_a + mean_b),
        hausdorff: max_a.max(max_b),
        diagonal: (hi - lo).length(),
    })
}

/// A camera of `width` x `height` pixels with `camera`'s pose (for probes at a resolution
/// other than the image's).
pub fn resized(camera: &Camera, width: u32, height: u32) -> Camera {
    Camera { width, height, ..*camera }
}

/// Per-pixel absolute difference scaled by `gain` (a heat map input for reports).
pub fn abs_difference(a: &RgbImage, b: &RgbImage, gain: f32) -> RgbImage {
    RgbImage::from_fn(a.width(), a.height(), |x, y| {
        let (p, q) = (a.get_pixel(x, y), b.get_pixel(x, y));
        let d = |i: usize| ((p[i] as f32 - q[i] as f32).abs() * gain).min(255.0) as u8;
        image::Rgb([d(0), d(1), d(2)])
    })
}

/// Mean of a slice (0 for an empty one).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 }
}

/// Median of a slice (NaN for an empty one).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(w: u32, h: u32, v: u8) -> RgbImage {
        RgbImage::from_pixel(w, h, image::Rgb([v, v, v]))
    }

    #[test]
    fn rmse_and_psnr_match_hand_computed_values() {
        // Every channel differs by 51/255 = 0.2: MSE 0.04, RMSE 0.2, PSNR 10 log10(25).
        let (a, b) = (constant(4, 3, 0), constant(4, 3, 51));
        assert!((rmse(&a, &b) - 0.2).abs() < 1e-12);
        assert!((psnr_db(&a, &b) - 10.0 * 25f64.log10()).abs() < 1e-9);
        assert_eq!(psnr_db(&a, &a), f64::INFINITY);
        // One pixel of four off by 1.0 in one channel: MSE = 1 / 12.
        let mut c = constant(2, 2, 0);
        c.put_pixel(1, 1, image::Rgb([255, 0, 0]));
        assert!((mse(&constant(2, 2, 0), &c) - 1.0 / 12.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_of_constant_images_is_the_luminance_term() {
        // Constant images have no variance: SSIM = (2ab + C1) / (a^2 + b^2 + C1).
        let (a, b) = (constant(16, 16, 51), constant(16, 16, 153));
        let (x, y, c1) = (0.2, 0.6, 1e-4);
        let want = (2.0 * x * y + c1) / (x * x + y * y + c1);
        assert!((ssim(&a, &b) - want).abs() < 1e-9, "{} vs {want}", ssim(&a, &b));
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_falls_with_noise_and_is_symmetric() {
        let a = RgbImage::from_fn(32, 32, |x, y| {
            let v = ((x * 7 + y * 3) % 255) as u8;
            image::Rgb([v, v, v])
        });
        let mut b = a.clone();
        for (i, p) in b.pixels_mut().enumerate() {
            if i % 3 == 0 {
                p.0 = [255 - p[0]; 3];
            }
        }
        let s = ssim(&a, &b);
        assert!(s < 0.9 && s > -1.0, "{s}");
        assert!((s - ssim(&b, &a)).abs() < 1e-12);
    }

    #[test]
    fn median_and_subsample() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        let pts: Vec<DVec3> = (0..10).map(|i| DVec3::splat(i as f64)).collect();
        assert_eq!(subsample(&pts, 5).len(), 5);
        assert_eq!(subsample(&pts, 100).len(), 10);
    }
}

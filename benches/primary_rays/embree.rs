//! The Embree side of the primary_rays benchmark (`--features embree`): Embree 3
//! (Debian's libembree-dev) through a minimal hand-written FFI, checked against the C
//! headers' layouts in /usr/include/embree3; scene builds, and the tile tracers raced
//! against ours: primary rays one at a time, in packets of 4, 8 and 16 and as streams,
//! shadow rays likewise with occlusion queries.

use std::ffi::{c_char, c_void};
use std::mem::{align_of, offset_of, size_of};
use std::sync::atomic::{AtomicIsize, Ordering};
use std::time::Instant;

use sdfmesh::geometry::RayStats;
use sdfmesh::mesh::TriangleMesh;

use super::{
    Agreement, Contender, Frame, MISS, OCCLUDED, Shadows, TILE_RAYS, TileFn, median, process_cpu_secs,
};

#[allow(non_camel_case_types, non_snake_case, dead_code)]
mod ffi {
    use std::ffi::{c_char, c_int, c_uint, c_void};

    pub type RTCDevice = *mut c_void;
    pub type RTCScene = *mut c_void;
    pub type RTCGeometry = *mut c_void;
    /// C enums are passed as `unsigned int`-sized values.
    pub type RTCEnum = c_uint;

    pub const RTC_INVALID_GEOMETRY_ID: c_uint = c_uint::MAX;
    pub const RTC_FORMAT_UINT3: RTCEnum = 0x5003;
    pub const RTC_FORMAT_FLOAT3: RTCEnum = 0x9003;
    pub const RTC_GEOMETRY_TYPE_TRIANGLE: RTCEnum = 0;
    pub const RTC_BUFFER_TYPE_INDEX: RTCEnum = 0;
    pub const RTC_BUFFER_TYPE_VERTEX: RTCEnum = 1;
    pub const RTC_BUILD_QUALITY_MEDIUM: RTCEnum = 1;
    pub const RTC_SCENE_FLAG_NONE: RTCEnum = 0;
    pub const RTC_SCENE_FLAG_ROBUST: RTCEnum = 1 << 2;
    pub const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: RTCEnum = 0;
    pub const RTC_INTERSECT_CONTEXT_FLAG_COHERENT: RTCEnum = 1;
    pub const RTC_DEVICE_PROPERTY_VERSION: RTCEnum = 0;
    pub const RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED: RTCEnum = 32;
    pub const RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED: RTCEnum = 33;
    pub const RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED: RTCEnum = 34;
    pub const RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED: RTCEnum = 35;
    pub const RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED: RTCEnum = 65;
    pub const RTC_DEVICE_PROPERTY_TASKING_SYSTEM: RTCEnum = 128;
    /// RTC_MAX_INSTANCE_LEVEL_COUNT in rtcore_config.h (Debian's build: 1).
    pub const MAX_INSTANCE_LEVEL_COUNT: usize = 1;

    /// `struct RTCRay` (rtcore_ray.h).
    #[repr(C, align(16))]
    #[derive(Clone, Copy, Debug, Default)]
    pub struct RTCRay {
        pub org_x: f32,
        pub org_y: f32,
        pub org_z: f32,
        pub tnear: f32,
        pub dir_x: f32,
        pub dir_y: f32,
        pub dir_z: f32,
        pub time: f32,
        pub tfar: f32,
        pub mask: c_uint,
        pub id: c_uint,
        pub flags: c_uint,
    }

    /// `struct RTCHit` (rtcore_ray.h).
    #[repr(C, align(16))]
    #[derive(Clone, Copy, Debug, Default)]
    pub struct RTCHit {
        pub Ng_x: f32,
        pub Ng_y: f32,
        pub Ng_z: f32,
        pub u: f32,
        pub v: f32,
        pub primID: c_uint,
        pub geomID: c_uint,
        pub instID: [c_uint; MAX_INSTANCE_LEVEL_COUNT],
    }

    /// `struct RTCRayHit` (rtcore_ray.h).
    #[repr(C)]
    #[derive(Clone, Copy, Debug, Default)]
    pub struct RTCRayHit {
        pub ray: RTCRay,
        pub hit: RTCHit,
    }

    /// `struct RTCRay4/8/16` (rtcore_ray.h): `N` rays as arrays per field. Aligned to 64
    /// bytes for every `N` (the headers ask 16, 32 and 64): the fields stay where C
    /// puts them, since each is `4 * N` bytes and the ray part is a multiple of 64.
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCRayN<const N: usize> {
        pub org_x: [f32; N],
        pub org_y: [f32; N],
        pub org_z: [f32; N],
        pub tnear: [f32; N],
        pub dir_x: [f32; N],
        pub dir_y: [f32; N],
        pub dir_z: [f32; N],
        pub time: [f32; N],
        pub tfar: [f32; N],
        pub mask: [c_uint; N],
        pub id: [c_uint; N],
        pub flags: [c_uint; N],
    }

    /// `struct RTCHit4/8/16` (rtcore_ray.h).
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCHitN<const N: usize> {
        pub Ng_x: [f32; N],
        pub Ng_y: [f32; N],
        pub Ng_z: [f32; N],
        pub u: [f32; N],
        pub v: [f32; N],
        pub primID: [c_uint; N],
        pub geomID: [c_uint; N],
        pub instID: [[c_uint; N]; MAX_INSTANCE_LEVEL_COUNT],
    }

    /// `struct RTCRayHit4/8/16` (rtcore_ray.h).
    #[repr(C)]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCRayHitN<const N: usize> {
        pub ray: RTCRayN<N>,
        pub hit: RTCHitN<N>,
    }

    impl<const N: usize> RTCRayN<N> {
        /// All lanes zero (inactive lanes are never read).
        pub fn zeroed() -> Self {
            RTCRayN {
                org_x: [0.0; N],
                org_y: [0.0; N],
                org_z: [0.0; N],
                tnear: [0.0; N],
                dir_x: [0.0; N],
                dir_y: [0.0; N],
                dir_z: [0.0; N],
                time: [0.0; N],
                tfar: [0.0; N],
                mask: [0; N],
                id: [0; N],
                flags: [0; N],
            }
        }
    }

    impl<const N: usize> RTCRayHitN<N> {
        /// All lanes zero but the hit's ids, which say "no hit".
        pub fn zeroed() -> Self {
            RTCRayHitN {
                ray: RTCRayN::zeroed(),
                hit: RTCHitN {
                    Ng_x: [0.0; N],
                    Ng_y: [0.0; N],
                    Ng_z: [0.0; N],
                    u: [0.0; N],
                    v: [0.0; N],
                    primID: [RTC_INVALID_GEOMETRY_ID; N],
                    geomID: [RTC_INVALID_GEOMETRY_ID; N],
                    instID: [[RTC_INVALID_GEOMETRY_ID; N]; MAX_INSTANCE_LEVEL_COUNT],
                },
            }
        }
    }

    /// The `valid` mask of `rtcIntersect4/8/16` and `rtcOccluded4/8/16`: -1 active, 0
    /// inactive, aligned like the packet.
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct ValidN<const N: usize>(pub [c_int; N]);

    /// `rtcIntersect4/8/16` for one `N`.
    pub type IntersectN<const N: usize> =
        unsafe extern "C" fn(*const ValidN<N>, RTCScene, *mut RTCIntersectContext, *mut RTCRayHitN<N>);

    /// `rtcOccluded4/8/16` for one `N`.
    pub type OccludedN<const N: usize> =
        unsafe extern "C" fn(*const ValidN<N>, RTCScene, *mut RTCIntersectContext, *mut RTCRayN<N>);

    pub type RTCFilterFunctionN = Option<unsafe extern "C" fn(args: *const c_void)>;

    /// `struct RTCIntersectContext` (rtcore_common.h) with RTC_MAX_INSTANCE_LEVEL_COUNT
    /// 1 (no `instStackSize`) and RTC_MIN_WIDTH 0 (no `minWidthDistanceFactor`).
    #[repr(C)]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCIntersectContext {
        pub flags: RTCEnum,
        pub filter: RTCFilterFunctionN,
        pub instID: [c_uint; MAX_INSTANCE_LEVEL_COUNT],
    }

    /// `rtcInitIntersectContext`, an inline function in rtcore_common.h.
    pub fn rtcInitIntersectContext() -> RTCIntersectContext {
        RTCIntersectContext {
            flags: RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
            filter: None,
            instID: [RTC_INVALID_GEOMETRY_ID; MAX_INSTANCE_LEVEL_COUNT],
        }
    }

    /// `struct RTCBounds` (rtcore_common.h).
    #[repr(C, align(16))]
    #[derive(Clone, Copy, Debug, Default)]
    pub struct RTCBounds {
        pub lower_x: f32,
        pub lower_y: f32,
        pub lower_z: f32,
        pub align0: f32,
        pub upper_x: f32,
        pub upper_y: f32,
        pub upper_z: f32,
        pub align1: f32,
    }

    pub type RTCMemoryMonitorFunction =
        Option<unsafe extern "C" fn(ptr: *mut c_void, bytes: isize, post: bool) -> bool>;

    #[link(name = "embree3")]
    unsafe extern "C" {
        pub fn rtcNewDevice(config: *const c_char) -> RTCDevice;
        pub fn rtcReleaseDevice(device: RTCDevice);
        pub fn rtcGetDeviceError(device: RTCDevice) -> RTCEnum;
        pub fn rtcGetDeviceProperty(device: RTCDevice, prop: RTCEnum) -> isize;
        pub fn rtcSetDeviceMemoryMonitorFunction(
            device: RTCDevice,
            monitor: RTCMemoryMonitorFunction,
            user: *mut c_void,
        );
        pub fn rtcNewScene(device: RTCDevice) -> RTCScene;
        pub fn rtcSetSceneBuildQuality(scene: RTCScene, quality: RTCEnum);
        pub fn rtcSetSceneFlags(scene: RTCScene, flags: RTCEnum);
        pub fn rtcNewGeometry(device: RTCDevice, kind: RTCEnum) -> RTCGeometry;
        pub fn rtcSetNewGeometryBuffer(
            geometry: RTCGeometry,
            kind: RTCEnum,
            slot: c_uint,
            format: RTCEnum,
            byte_stride: usize,
            item_count: usize,
        ) -> *mut c_void;
        pub fn rtcCommitGeometry(geometry: RTCGeometry);
        pub fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
        pub fn rtcReleaseGeometry(geometry: RTCGeometry);
        pub fn rtcCommitScene(scene: RTCScene);
        pub fn rtcGetSceneBounds(scene: RTCScene, bounds: *mut RTCBounds);
        pub fn rtcIntersect1(scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
        pub fn rtcIntersect4(
            valid: *const ValidN<4>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHitN<4>,
        );
        pub fn rtcIntersect8(
            valid: *const ValidN<8>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHitN<8>,
        );
        pub fn rtcIntersect16(
            valid: *const ValidN<16>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHitN<16>,
        );
        pub fn rtcIntersect1M(
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHit,
            m: c_uint,
            byte_stride: usize,
        );
        pub fn rtcOccluded1(scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay);
        pub fn rtcOccluded4(
            valid: *const ValidN<4>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            ray: *mut RTCRayN<4>,
        );
        pub fn rtcOccluded8(
            valid: *const ValidN<8>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            ray: *mut RTCRayN<8>,
        );
        pub fn rtcOccluded16(
            valid: *const ValidN<16>,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            ray: *mut RTCRayN<16>,
        );
        pub fn rtcOccluded1M(
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            ray: *mut RTCRay,
            m: c_uint,
            byte_stride: usize,
        );
        pub fn rtcReleaseScene(scene: RTCScene);
    }
}

use ffi::*;

// Layouts as compiled C reports them for Debian's embree 3.13.5 (x86-64):
// RTCRayHit 80/16 (hit at 48, tfar at 32, geomID at 72), RTCRayHit4 320/16 (hit at 192),
// RTCRayHit8 640/32 (hit at 384), RTCRayHit16 1280/64 (hit at 768), RTCRay4/8/16
// 192/384/768, RTCIntersectContext 24/8 (filter at 8, instID at 16), RTCBounds 32/16.
// Our packets are 64-byte aligned, which keeps these offsets and sizes.
const _: () = {
    assert!(size_of::<RTCRay>() == 48 && align_of::<RTCRay>() == 16);
    assert!(size_of::<RTCHit>() == 32 && align_of::<RTCHit>() == 16);
    assert!(size_of::<RTCRayHit>() == 80 && align_of::<RTCRayHit>() == 16);
    assert!(offset_of!(RTCRayHit, hit) == 48);
    assert!(offset_of!(RTCRay, tfar) == 32);
    assert!(offset_of!(RTCHit, primID) == 20 && offset_of!(RTCHit, geomID) == 24);
    assert!(size_of::<RTCRayHitN<4>>() == 320 && offset_of!(RTCRayHitN<4>, hit) == 192);
    assert!(size_of::<RTCRayHitN<8>>() == 640 && offset_of!(RTCRayHitN<8>, hit) == 384);
    assert!(size_of::<RTCRayHitN<16>>() == 1280 && offset_of!(RTCRayHitN<16>, hit) == 768);
    assert!(size_of::<RTCRayN<4>>() == 192 && size_of::<RTCRayN<8>>() == 384);
    assert!(size_of::<RTCRayN<16>>() == 768 && align_of::<RTCRayN<16>>() == 64);
    assert!(offset_of!(RTCRayN<8>, tfar) == 256 && offset_of!(RTCHitN<8>, geomID) == 192);
    assert!(size_of::<RTCIntersectContext>() == 24);
    assert!(offset_of!(RTCIntersectContext, filter) == 8);
    assert!(offset_of!(RTCIntersectContext, instID) == 16);
    assert!(size_of::<RTCBounds>() == 32 && align_of::<RTCBounds>() == 16);
};

/// Tracer name of the one-ray-at-a-time Embree rows.
pub const ONE_RAY: &str = "embree rtcIntersect1";
/// Tracer name of the Embree rows of 8-ray packets.
pub const PACKET8: &str = "embree rtcIntersect8";
/// Tracer name of the one-ray-at-a-time Embree shadow rows.
pub const OCCLUDED1: &str = "embree rtcOccluded1";
/// Tracer name of the Embree shadow rows of 8-ray packets.
pub const OCCLUDED8: &str = "embree rtcOccluded8";

/// Net bytes the device's memory monitor has seen allocated.
static DEVICE_BYTES: AtomicIsize = AtomicIsize::new(0);

unsafe extern "C" fn monitor(_user: *mut c_void, bytes: isize, _post: bool) -> bool {
    DEVICE_BYTES.fetch_add(bytes, Ordering::Relaxed);
    true
}

/// An Embree device (released on drop).
struct Device(RTCDevice);

impl Device {
    fn new(config: &std::ffi::CStr) -> Self {
        // SAFETY: a NUL-terminated config string; the handle is checked below.
        let d = unsafe { rtcNewDevice(config.as_ptr() as *const c_char) };
        assert!(!d.is_null(), "rtcNewDevice failed");
        Device(d)
    }

    fn check(&self, what: &str) {
        // SAFETY: a live device.
        let e = unsafe { rtcGetDeviceError(self.0) };
        assert_eq!(e, 0, "embree error {e} after {what}");
    }

    fn property(&self, p: RTCEnum) -> isize {
        // SAFETY: a live device.
        unsafe { rtcGetDeviceProperty(self.0, p) }
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: released once; scenes hold their own reference to the device.
        unsafe { rtcReleaseDevice(self.0) }
    }
}

/// A committed Embree scene holding one triangle geometry.
struct Scene(RTCScene);

// SAFETY: a committed scene is immutable and Embree allows concurrent intersect calls.
unsafe impl Send for Scene {}
// SAFETY: as above.
unsafe impl Sync for Scene {}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: released once.
        unsafe { rtcReleaseScene(self.0) }
    }
}

/// Builds a scene of `mesh` on `device`, timing scene creation, buffer copies and
/// the commit.
fn build(device: &Device, mesh: &TriangleMesh, flags: RTCEnum) -> Built {
    let cpu0 = process_cpu_secs();
    let start = Instant::now();
    // SAFETY: valid device; the buffers Embree returns have the requested sizes
    // (item_count * stride bytes), written in full before the commit.
    let scene = unsafe {
        let scene = rtcNewScene(device.0);
        rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
        rtcSetSceneFlags(scene, flags);
        let geom = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_TRIANGLE);
        let n = mesh.positions.len();
        let vb =
            rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, n) as *mut f32;
        assert!(!vb.is_null(), "vertex buffer");
        let vb = std::slice::from_raw_parts_mut(vb, 3 * n);
        for (dst, p) in vb.chunks_exact_mut(3).zip(&mesh.positions) {
            dst.copy_from_slice(&p.to_array());
        }
        let m = mesh.triangles.len();
        let ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, m) as *mut u32;
        assert!(!ib.is_null(), "index buffer");
        let ib = std::slice::from_raw_parts_mut(ib, 3 * m);
        for (dst, t) in ib.chunks_exact_mut(3).zip(&mesh.triangles) {
            dst.copy_from_slice(t);
        }
        rtcCommitGeometry(geom);
        rtcAttachGeometry(scene, geom);
        rtcReleaseGeometry(geom);
        rtcCommitScene(scene);
        Scene(scene)
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    device.check("scene build");
    Built {
        scene,
        ms,
        cpu_ms: cpu0.zip(process_cpu_secs()).map(|(a, b)| (b - a) * 1e3),
        buffer_bytes: 12 * (mesh.positions.len() + mesh.triangles.len()),
    }
}

/// A scene just built, with its build's wall and process CPU time.
struct Built {
    scene: Scene,
    ms: f64,
    cpu_ms: Option<f64>,
    buffer_bytes: usize,
}

#[inline]
fn ray_hit(frame: &Frame, x: u32, y: u32) -> RTCRayHit {
    let r = frame.camera.ray(x, y);
    RTCRayHit {
        ray: RTCRay {
            org_x: r.origin.x,
            org_y: r.origin.y,
            org_z: r.origin.z,
            tnear: 0.0,
            dir_x: r.dir.x,
            dir_y: r.dir.y,
            dir_z: r.dir.z,
            time: 0.0,
            tfar: f32::INFINITY,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        },
        hit: RTCHit {
            geomID: RTC_INVALID_GEOMETRY_ID,
            instID: [RTC_INVALID_GEOMETRY_ID; MAX_INSTANCE_LEVEL_COUNT],
            ..RTCHit::default()
        },
    }
}

#[inline]
fn result(rh: &RTCRayHit) -> f32 {
    if rh.hit.geomID != RTC_INVALID_GEOMETRY_ID { rh.ray.tfar } else { MISS }
}

/// Embree one ray at a time.
fn tile_1(scene: &Scene) -> TileFn<'_> {
    Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
        let o = frame.origin(tile);
        let mut ctx = rtcInitIntersectContext();
        let mut stats = RayStats::default();
        for (s, slot) in slots.iter_mut().enumerate() {
            if let Some((x, y)) = frame.pixel(o, s) {
                let mut rh = ray_hit(frame, x, y);
                // SAFETY: committed scene, initialised context and ray.
                unsafe { rtcIntersect1(scene.0, &mut ctx, &mut rh) };
                stats.rays += 1;
                *slot = result(&rh);
            }
        }
        stats
    })
}

/// A context for coherent rays (packets and streams of neighbours).
fn coherent() -> RTCIntersectContext {
    let mut ctx = rtcInitIntersectContext();
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    ctx
}

/// Embree packets of `N` rays (`rtcIntersect4/8/16`), coherent context: `N`
/// consecutive rays of the tile in the renderer's order ([`Frame::packet_order`]: a
/// packet of 4 is half of one of the renderer's 4x2 packets, one of 16 two of them).
fn tile_n<const N: usize>(scene: &Scene, intersect: IntersectN<N>) -> TileFn<'_> {
    Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
        let o = frame.origin(tile);
        let (order, n) = frame.packet_order(tile);
        let mut ctx = coherent();
        for group in order[..n].chunks(N) {
            let mut valid = ValidN([0; N]);
            let mut p = RTCRayHitN::<N>::zeroed();
            for (k, &s) in group.iter().enumerate() {
                let (x, y) = frame.pixel(o, s as usize).expect("packet_order keeps pixels inside the image");
                let r = frame.camera.ray(x, y);
                valid.0[k] = -1;
                p.ray.org_x[k] = r.origin.x;
                p.ray.org_y[k] = r.origin.y;
                p.ray.org_z[k] = r.origin.z;
                p.ray.dir_x[k] = r.dir.x;
                p.ray.dir_y[k] = r.dir.y;
                p.ray.dir_z[k] = r.dir.z;
                p.ray.tfar[k] = f32::INFINITY;
                p.ray.mask[k] = u32::MAX;
            }
            // SAFETY: 64-byte aligned mask and packet of the layout the headers give
            // (checked above), committed scene.
            unsafe { intersect(&valid, scene.0, &mut ctx, &mut p) };
            for (k, &s) in group.iter().enumerate() {
                slots[s as usize] =
                    if p.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID { p.ray.tfar[k] } else { MISS };
            }
        }
        RayStats { rays: n as u64, ..RayStats::default() }
    })
}

/// Embree ray stream: one tile's rays in the renderer's order in one `rtcIntersect1M`
/// call, coherent context.
fn tile_1m(scene: &Scene) -> TileFn<'_> {
    Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
        let o = frame.origin(tile);
        let (order, n) = frame.packet_order(tile);
        let mut ctx = coherent();
        let mut rays = [RTCRayHit::default(); TILE_RAYS];
        for (rh, &s) in rays.iter_mut().zip(&order[..n]) {
            let (x, y) = frame.pixel(o, s as usize).expect("packet_order keeps pixels inside the image");
            *rh = ray_hit(frame, x, y);
        }
        // SAFETY: `n` contiguous initialised rays with their natural stride.
        unsafe { rtcIntersect1M(scene.0, &mut ctx, rays.as_mut_ptr(), n as u32, size_of::<RTCRayHit>()) };
        for (rh, &s) in rays[..n].iter().zip(&order[..n]) {
            slots[s as usize] = result(rh);
        }
        RayStats { rays: n as u64, ..RayStats::default() }
    })
}

/// Shadow ray `j` of `sh` as an Embree ray: `t` in [0, distance to the light].
#[inline]
fn shadow_ray(sh: &Shadows, j: usize) -> RTCRay {
    let r = &sh.rays[j];
    RTCRay {
        org_x: r.origin.x,
        org_y: r.origin.y,
        org_z: r.origin.z,
        tnear: 0.0,
        dir_x: r.dir.x,
        dir_y: r.dir.y,
        dir_z: r.dir.z,
        time: 0.0,
        tfar: sh.reach[j],
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

/// The output of an Embree occlusion query: it sets `tfar` to -inf where occluded.
#[inline]
fn occlusion(tfar: f32) -> f32 {
    if tfar == f32::NEG_INFINITY { OCCLUDED } else { MISS }
}

/// Embree shadow rays one at a time (`rtcOccluded1`), incoherent context.
fn shadow_1<'a>(scene: &'a Scene, sh: &'a Shadows) -> TileFn<'a> {
    Box::new(move |_frame: &Frame, tile: usize, slots: &mut [f32]| {
        let r = sh.of_tile(tile);
        let mut ctx = rtcInitIntersectContext();
        let stats = RayStats { rays: r.len() as u64, ..RayStats::default() };
        for j in r {
            let mut ray = shadow_ray(sh, j);
            // SAFETY: committed scene, initialised context and ray.
            unsafe { rtcOccluded1(scene.0, &mut ctx, &mut ray) };
            slots[sh.slot[j] as usize] = occlusion(ray.tfar);
        }
        stats
    })
}

/// Embree shadow rays in packets of `N` consecutive rays of the tile's
/// (`rtcOccluded4/8/16`), coherent context.
fn shadow_n<'a, const N: usize>(scene: &'a Scene, sh: &'a Shadows, occluded: OccludedN<N>) -> TileFn<'a> {
    Box::new(move |_frame: &Frame, tile: usize, slots: &mut [f32]| {
        let r = sh.of_tile(tile);
        let stats = RayStats { rays: r.len() as u64, ..RayStats::default() };
        let mut ctx = coherent();
        for start in r.clone().step_by(N) {
            let group = start..(start + N).min(r.end);
            let mut valid = ValidN([0; N]);
            let mut p = RTCRayN::<N>::zeroed();
            for (k, j) in group.clone().enumerate() {
                let (o, d) = (sh.rays[j].origin, sh.rays[j].dir);
                valid.0[k] = -1;
                p.org_x[k] = o.x;
                p.org_y[k] = o.y;
                p.org_z[k] = o.z;
                p.dir_x[k] = d.x;
                p.dir_y[k] = d.y;
                p.dir_z[k] = d.z;
                p.tfar[k] = sh.reach[j];
                p.mask[k] = u32::MAX;
            }
            // SAFETY: 64-byte aligned mask and packet of the layout the headers give
            // (checked above), committed scene.
            unsafe { occluded(&valid, scene.0, &mut ctx, &mut p) };
            for (k, j) in group.enumerate() {
                slots[sh.slot[j] as usize] = occlusion(p.tfar[k]);
            }
        }
        stats
    })
}

/// Embree shadow-ray stream: one tile's shadow rays in one `rtcOccluded1M` call,
/// coherent context.
fn shadow_1m<'a>(scene: &'a Scene, sh: &'a Shadows) -> TileFn<'a> {
    Box::new(move |_frame: &Frame, tile: usize, slots: &mut [f32]| {
        let r = sh.of_tile(tile);
        let m = r.len();
        let mut ctx = coherent();
        let mut rays = [RTCRay::default(); TILE_RAYS];
        for (ray, j) in rays.iter_mut().zip(r.clone()) {
            *ray = shadow_ray(sh, j);
        }
        // SAFETY: `m` contiguous initialised rays with their natural stride.
        unsafe { rtcOccluded1M(scene.0, &mut ctx, rays.as_mut_ptr(), m as u32, size_of::<RTCRay>()) };
        for (ray, j) in rays[..m].iter().zip(r) {
            slots[sh.slot[j] as usize] = occlusion(ray.tfar);
        }
        RayStats { rays: m as u64, ..RayStats::default() }
    })
}

/// Embree's side of one mesh's benchmark.
pub struct Bench {
    // Field order: scenes drop before the device.
    scene: Scene,
    robust: Scene,
    build_ms: f64,
    bytes: String,
    /// Whether the device traces packets of 4 / 16 rays natively (else they are not
    /// raced: emulated packets say nothing about Embree's packet kernels).
    native4: bool,
    native16: bool,
    _device: Device,
}

impl Bench {
    pub fn new(mesh: &TriangleMesh, builds: usize) -> Self {
        let device = Device::new(c"verbose=0");
        // SAFETY: a plain function and no user data.
        unsafe { rtcSetDeviceMemoryMonitorFunction(device.0, Some(monitor), std::ptr::null_mut()) };
        let native4 = device.property(RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED) != 0;
        let native16 = device.property(RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) != 0;
        println!(
            "embree {} (tasking system {}, native ray4 {} ray8 {} ray16 {}, ray streams {}, backface \
             culling {})",
            device.property(RTC_DEVICE_PROPERTY_VERSION),
            match device.property(RTC_DEVICE_PROPERTY_TASKING_SYSTEM) {
                0 => "internal",
                1 => "TBB",
                2 => "PPL",
                _ => "?",
            },
            u8::from(native4),
            device.property(RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED),
            u8::from(native16),
            device.property(RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED),
            device.property(RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED),
        );
        let mut times = Vec::new();
        let mut cpu_times = Vec::new();
        let mut kept = None;
        let mut bytes = (0, 0);
        for _ in 0..builds.max(1) {
            drop(kept.take());
            let before = DEVICE_BYTES.load(Ordering::Relaxed);
            let b = build(&device, mesh, RTC_SCENE_FLAG_NONE);
            bytes = (DEVICE_BYTES.load(Ordering::Relaxed) - before, b.buffer_bytes);
            times.push(b.ms);
            cpu_times.extend(b.cpu_ms);
            kept = Some(b.scene);
        }
        let scene = kept.expect("built");
        // Build time with Embree's builder limited to one thread, for reference.
        let device1 = Device::new(c"verbose=0,threads=1");
        let (mut times1, mut cpu_times1) = (Vec::new(), Vec::new());
        for _ in 0..builds.max(1) {
            let b = build(&device1, mesh, RTC_SCENE_FLAG_NONE);
            times1.push(b.ms);
            cpu_times1.extend(b.cpu_ms);
        }
        drop(device1);
        let robust = build(&device, mesh, RTC_SCENE_FLAG_ROBUST).scene;
        let mut b = RTCBounds::default();
        // SAFETY: committed scene, aligned output.
        unsafe { rtcGetSceneBounds(scene.0, &mut b) };
        let (lo, hi) = mesh.bounds().expect("nonempty mesh");
        let bounds_ok = (lo.x, lo.y, lo.z, hi.x, hi.y, hi.z)
            == (b.lower_x, b.lower_y, b.lower_z, b.upper_x, b.upper_y, b.upper_z);
        let build_ms = median(&times);
        let cpu = |v: &[f64]| if v.is_empty() { "-".to_string() } else { format!("{:.1}", median(v)) };
        println!(
            "embree build (quality medium): {build_ms:.1} ms median of {} ({} ms CPU) on the default \
             device (TBB, all hardware threads), {:.1} ms ({} ms CPU) with threads=1; \
             rtcGetSceneBounds [{:.4} {:.4} {:.4}]..[{:.4} {:.4} {:.4}] {}",
            times.len(),
            cpu(&cpu_times),
            median(&times1),
            cpu(&cpu_times1),
            b.lower_x,
            b.lower_y,
            b.lower_z,
            b.upper_x,
            b.upper_y,
            b.upper_z,
            if bounds_ok { "equals the mesh's bounds" } else { "DIFFERS from the mesh's bounds" }
        );
        let (total, buffers) = bytes;
        Bench {
            scene,
            robust,
            build_ms,
            bytes: format!("~{}/~{}", total, total - buffers as isize),
            native4,
            native16,
            _device: device,
        }
    }

    /// The Embree primary-ray tracers to race.
    pub fn contenders(&self) -> Vec<Contender<'_>> {
        let mut v = vec![Contender::new(ONE_RAY, tile_1(&self.scene))];
        if self.native4 {
            v.push(Contender::new("embree rtcIntersect4", tile_n::<4>(&self.scene, rtcIntersect4)));
        }
        v.push(Contender::new(PACKET8, tile_n::<8>(&self.scene, rtcIntersect8)));
        if self.native16 {
            v.push(Contender::new("embree rtcIntersect16", tile_n::<16>(&self.scene, rtcIntersect16)));
        }
        v.push(Contender::new("embree rtcIntersect1M", tile_1m(&self.scene)));
        self.label(&mut v);
        // Watertight like ours (RTC_SCENE_FLAG_ROBUST), one ray at a time.
        v.push(Contender::new("embree robust Isect1", tile_1(&self.robust)));
        v
    }

    /// The Embree shadow-ray tracers to race on `sh`.
    pub fn shadow_contenders<'a>(&'a self, sh: &'a Shadows) -> Vec<Contender<'a>> {
        let mut v = vec![Contender::new(OCCLUDED1, shadow_1(&self.scene, sh))];
        if self.native4 {
            v.push(Contender::new("embree rtcOccluded4", shadow_n::<4>(&self.scene, sh, rtcOccluded4)));
        }
        v.push(Contender::new(OCCLUDED8, shadow_n::<8>(&self.scene, sh, rtcOccluded8)));
        if self.native16 {
            v.push(Contender::new("embree rtcOccluded16", shadow_n::<16>(&self.scene, sh, rtcOccluded16)));
        }
        v.push(Contender::new("embree rtcOccluded1M", shadow_1m(&self.scene, sh)));
        self.label(&mut v);
        v
    }

    /// Gives `contenders` (all tracing the default scene) its build time and bytes.
    fn label(&self, contenders: &mut [Contender<'_>]) {
        for c in contenders {
            c.build_ms = Some(self.build_ms);
            c.bytes = self.bytes.clone();
        }
    }

    /// Agreement of `ours` (a frame's output) with Embree's robust (watertight) mode.
    pub fn robust_agreement(&self, frame: &Frame, ours: &[f32]) -> Agreement {
        let mut c = Contender::new("embree robust", tile_1(&self.robust));
        c.frame(&super::pool(1), frame);
        Agreement::of(frame, ours, &c.out)
    }
}

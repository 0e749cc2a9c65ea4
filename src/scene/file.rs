//! The TOML scene file format: parsing with serde, validation with file:line:column
//! errors, and conversion into a [`Scene`].
//!
//! The format is documented in `docs/scene-format.md`. Parsing happens in two steps:
//! serde reads the text into `Raw*` structs (every table denies unknown keys, every value
//! that is validated keeps its byte span through [`toml::Spanned`], and every number is
//! checked to be finite while it is read), then the structs are validated and converted
//! into the [`Scene`] types. Every error names the file, the 1-based line and column of
//! the offending key or value, the key path (`objects[1].children[0].radius`) and the
//! problem, on one line.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::marker::PhantomData;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use glam::{DVec3, UVec3, Vec3};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::{Camera, Light, Material, Scene, Settings};
use crate::base::MaterialId;
use crate::base::transform::{Transform, TransformDesc};
use crate::error::{Error, Location, Result};
use crate::scene::shape::{CsgOp, Object, ObjectKind, Primitive, Shading};

/// Largest accepted image width or height, pixels.
pub const MAX_IMAGE_SIZE: u32 = 16384;

/// Largest accepted `settings.max_depth` (reflection/refraction recursion depth).
pub const MAX_RECURSION_DEPTH: u32 = 100;

/// Every value of an object's `type` key.
pub const OBJECT_TYPES: [&str; 19] = [
    "sphere",
    "plane",
    "box",
    "ellipsoid",
    "cylinder",
    "cone",
    "torus",
    "triangle",
    "capsule",
    "union",
    "subtraction",
    "intersection",
    "smooth_union",
    "smooth_subtraction",
    "smooth_intersection",
    "repeat",
    "mesh",
    "grid",
    "implicit",
];

/// Every value of a light's `type` key.
pub const LIGHT_TYPES: [&str; 3] = ["ambient", "point", "directional"];

/// Keys every object accepts.
const OBJECT_COMMON_KEYS: [&str; 6] = ["type", "name", "material", "translate", "rotate", "scale"];

/// The keys an object of type `ty` accepts besides [`OBJECT_COMMON_KEYS`].
fn object_type_keys(ty: &str) -> Option<&'static [&'static str]> {
    Some(match ty {
        "sphere" => &["radius"],
        "plane" => &["normal", "offset", "point"],
        "box" => &["half_size"],
        "ellipsoid" => &["radii"],
        "cylinder" => &["radius", "height"],
        "cone" => &["radius_bottom", "radius_top", "height"],
        "torus" => &["major_radius", "minor_radius"],
        "triangle" => &["a", "b", "c"],
        "capsule" => &["a", "b", "radius"],
        "union" | "subtraction" | "intersection" => &["children"],
        "smooth_union" | "smooth_subtraction" | "smooth_intersection" => &["children", "blend"],
        "repeat" => &["period", "count", "child"],
        "mesh" => &["path", "shading"],
        "grid" | "implicit" => &["path"],
        _ => return None,
    })
}

/// The keys a light of type `ty` accepts besides `type`.
fn light_type_keys(ty: &str) -> Option<&'static [&'static str]> {
    Some(match ty {
        "ambient" => &["intensity"],
        "point" => &["position", "intensity", "color"],
        "directional" => &["direction", "intensity", "color"],
        _ => return None,
    })
}

/// Reads and parses the scene file at `path`.
pub fn load_scene(path: &Path) -> Result<Scene> {
    let text = crate::files::read_input_text(path, crate::files::MAX_TEXT_BYTES)?;
    parse_scene(&text, path)
}

/// Parses scene text; `path` is used in messages and to resolve relative paths.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene> {
    let raw: RawScene = toml::from_str(text).map_err(|e| translate_de_error(text, path, &e))?;
    let cx = Cx { text, path };

    let camera = match &raw.camera {
        Some(c) => cx.camera(c)?,
        None => Camera::default(),
    };
    let settings = match &raw.settings {
        Some(s) => cx.settings(s)?,
        None => Settings::default(),
    };
    let mut lights = Vec::new();
    for (i, l) in raw.lights.iter().flatten().enumerate() {
        lights.push(cx.light(l, &format!("lights[{i}]"))?);
    }

    // Materials in file order (the map is keyed by name; sort by where the name stands).
    let mut entries: Vec<_> = raw.materials.iter().flatten().collect();
    entries.sort_by_key(|(name, _)| name.span().start);
    let mut materials = Materials::default();
    for (name, m) in entries {
        let material = cx.material(name.get_ref(), m)?;
        materials.by_name.insert(name.get_ref().clone(), materials.list.len() as MaterialId);
        materials.list.push(material);
    }

    let mut objects = Vec::new();
    for (i, o) in raw.objects.iter().flatten().enumerate() {
        objects.push(cx.object(&o.get_ref().0, &format!("objects[{i}]"), None, &mut materials)?);
    }
    if materials.list.is_empty() {
        // `Scene::materials` is never empty.
        materials.default_id();
    }

    Ok(Scene { camera, settings, lights, materials: materials.list, objects })
}

// ---------------------------------------------------------------------------------------
// Value types read by serde.

/// A finite number (TOML integer or float) that fits in an `f32`.
#[derive(Clone, Copy, Debug)]
struct Num(f32);

fn finite_f32<E: de::Error>(v: f64) -> Result<f32, E> {
    if v.is_nan() {
        return Err(E::custom("must be a finite number, got nan"));
    }
    if v.is_infinite() {
        let s = if v > 0.0 { "inf" } else { "-inf" };
        return Err(E::custom(format!("must be a finite number, got {s}")));
    }
    let f = v as f32;
    if !f.is_finite() {
        return Err(E::custom(format!("{v:e} is out of range (magnitude must be below 3.4e38)")));
    }
    Ok(f)
}

struct NumVisitor;

impl<'de> Visitor<'de> for NumVisitor {
    type Value = f32;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number")
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f32, E> {
        Ok(v as f32)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f32, E> {
        Ok(v as f32)
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f32, E> {
        finite_f32(v)
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumVisitor).map(Num)
    }
}

/// Reads exactly three numbers from a sequence.
fn seq3<'de, A: SeqAccess<'de>>(mut seq: A) -> Result<Vec3, A::Error> {
    let mut v = [0.0f32; 3];
    let mut n = 0usize;
    while let Some(Num(x)) = seq.next_element()? {
        if n < 3 {
            v[n] = x;
        }
        n += 1;
    }
    if n != 3 {
        return Err(de::Error::custom(format!(
            "expected an array of 3 numbers [x, y, z], got {n} element{}",
            if n == 1 { "" } else { "s" }
        )));
    }
    Ok(Vec3::from_array(v))
}

/// A vector written `[x, y, z]` with finite components.
#[derive(Clone, Copy, Debug)]
struct V3(Vec3);

impl<'de> Deserialize<'de> for V3 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = V3;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array of 3 numbers [x, y, z]")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<V3, A::Error> {
                seq3(seq).map(V3)
            }
        }
        d.deserialize_any(V)
    }
}

/// A scale: one number for every axis or `[sx, sy, sz]`.
#[derive(Clone, Copy, Debug)]
enum Scale {
    Uniform(f32),
    PerAxis(Vec3),
}

impl<'de> Deserialize<'de> for Scale {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Scale;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of 3 numbers [sx, sy, sz]")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Scale, E> {
                NumVisitor.visit_i64(v).map(Scale::Uniform)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Scale, E> {
                NumVisitor.visit_u64(v).map(Scale::Uniform)
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Scale, E> {
                NumVisitor.visit_f64(v).map(Scale::Uniform)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Scale, A::Error> {
                seq3(seq).map(Scale::PerAxis)
            }
        }
        d.deserialize_any(V)
    }
}

/// A TOML integer.
#[derive(Clone, Copy, Debug)]
struct Int(i64);

impl<'de> Deserialize<'de> for Int {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Int;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an integer")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Int, E> {
                Ok(Int(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Int, E> {
                i64::try_from(v).map(Int).map_err(|_| E::custom(format!("integer {v} is out of range")))
            }
        }
        d.deserialize_any(V)
    }
}

/// Three integers `[nx, ny, nz]`.
#[derive(Clone, Copy, Debug)]
struct Int3([i64; 3]);

impl<'de> Deserialize<'de> for Int3 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Int3;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array of 3 integers [nx, ny, nz]")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Int3, A::Error> {
                let mut v = [0i64; 3];
                let mut n = 0usize;
                while let Some(Int(x)) = seq.next_element()? {
                    if n < 3 {
                        v[n] = x;
                    }
                    n += 1;
                }
                if n != 3 {
                    return Err(de::Error::custom(format!(
                        "expected an array of 3 integers [nx, ny, nz], got {n} element{}",
                        if n == 1 { "" } else { "s" }
                    )));
                }
                Ok(Int3(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// A TOML table read as `T`. serde-derived structs also accept arrays (fields in order);
/// scene tables must be tables, so an array is rejected with a clear message.
struct Table<T>(T);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Table<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = T;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a table")
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<T, A::Error> {
                T::deserialize(de::value::MapAccessDeserializer::new(map))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, _: A) -> Result<T, A::Error> {
                Err(de::Error::custom(
                    "expected a single table, got an array (write `[name]`, not `[[name]]`)",
                ))
            }
        }
        d.deserialize_any(V(PhantomData)).map(Table)
    }
}

// ---------------------------------------------------------------------------------------
// The file's tables as serde reads them.

type S<T> = Option<Spanned<T>>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawScene {
    camera: S<Table<RawCamera>>,
    settings: S<Table<RawSettings>>,
    lights: Option<Vec<Spanned<Table<RawLight>>>>,
    materials: Option<BTreeMap<Spanned<String>, Spanned<Table<RawMaterial>>>>,
    objects: Option<Vec<Spanned<Table<RawObject>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawCamera {
    position: S<V3>,
    look_at: S<V3>,
    direction: S<V3>,
    up: S<V3>,
    fov: S<Num>,
    width: S<Int>,
    height: S<Int>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawSettings {
    max_depth: S<Int>,
    background: S<V3>,
    max_distance: S<Num>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawLight {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    intensity: S<Num>,
    position: S<V3>,
    direction: S<V3>,
    color: S<V3>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawMaterial {
    color: Spanned<V3>,
    ka: S<Num>,
    kd: S<Num>,
    ks: S<Num>,
    shininess: S<Num>,
    reflectivity: S<Num>,
    transparency: S<Num>,
    ior: S<Num>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "a table")]
struct RawObject {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    name: S<String>,
    material: S<String>,
    translate: S<V3>,
    rotate: S<V3>,
    scale: S<Scale>,
    radius: S<Num>,
    normal: S<V3>,
    offset: S<Num>,
    point: S<V3>,
    half_size: S<V3>,
    radii: S<V3>,
    height: S<Num>,
    radius_bottom: S<Num>,
    radius_top: S<Num>,
    major_radius: S<Num>,
    minor_radius: S<Num>,
    a: S<V3>,
    b: S<V3>,
    c: S<V3>,
    blend: S<Num>,
    period: S<V3>,
    count: S<Int3>,
    children: S<Vec<Spanned<Table<RawObject>>>>,
    child: S<Box<Table<RawObject>>>,
    path: S<String>,
    shading: S<String>,
}

/// The names and value spans of the present optional fields of a raw struct.
macro_rules! present_keys {
    ($raw:expr; $($field:ident),* $(,)?) => {{
        let mut keys: Vec<(&'static str, Range<usize>)> = Vec::new();
        $(
            if let Some(v) = &$raw.$field {
                keys.push((stringify!($field), v.span()));
            }
        )*
        keys
    }};
}

impl RawObject {
    /// The type-specific keys that are present (the common keys are valid everywhere).
    fn specific_keys(&self) -> Vec<(&'static str, Range<usize>)> {
        present_keys!(self; radius, normal, offset, point, half_size, radii, height,
            radius_bottom, radius_top, major_radius, minor_radius, a, b, c, blend, period,
            count, children, child, path, shading)
    }
}

impl RawLight {
    fn specific_keys(&self) -> Vec<(&'static str, Range<usize>)> {
        present_keys!(self; intensity, position, direction, color)
    }
}

// ---------------------------------------------------------------------------------------
// Validation and conversion.

/// Materials defined so far and the lazily added default.
#[derive(Default)]
struct Materials {
    list: Vec<Material>,
    by_name: HashMap<String, MaterialId>,
}

impl Materials {
    /// The material named "default", added (as [`Material::default`]) on first use unless
    /// the file defines one.
    fn default_id(&mut self) -> MaterialId {
        if let Some(&id) = self.by_name.get("default") {
            return id;
        }
        let id = self.list.len() as MaterialId;
        self.list.push(Material::default());
        self.by_name.insert("default".into(), id);
        id
    }
}

/// The text and file name errors refer to.
struct Cx<'a> {
    text: &'a str,
    path: &'a Path,
}

impl Cx<'_> {
    fn err(&self, span: Range<usize>, msg: impl fmt::Display) -> Error {
        Error::input(self.path, Some(location(self.text, span.start)), msg)
    }

    fn positive(&self, v: &Spanned<Num>, what: &str) -> Result<f32> {
        let x = v.get_ref().0;
        if x > 0.0 { Ok(x) } else { Err(self.err(v.span(), format!("{what}: must be > 0, got {x}"))) }
    }

    fn non_negative(&self, v: &Spanned<Num>, what: &str) -> Result<f32> {
        let x = v.get_ref().0;
        if x >= 0.0 { Ok(x) } else { Err(self.err(v.span(), format!("{what}: must be >= 0, got {x}"))) }
    }

    fn unit_interval(&self, v: &Spanned<Num>, what: &str) -> Result<f32> {
        let x = v.get_ref().0;
        if (0.0..=1.0).contains(&x) {
            Ok(x)
        } else {
            Err(self.err(v.span(), format!("{what}: must be between 0 and 1, got {x}")))
        }
    }

    fn positive3(&self, v: &Spanned<V3>, what: &str) -> Result<Vec3> {
        let x = v.get_ref().0;
        if x.cmpgt(Vec3::ZERO).all() {
            Ok(x)
        } else {
            Err(self.err(v.span(), format!("{what}: every component must be > 0, got {}", fmt_v3(x))))
        }
    }

    fn color(&self, v: &Spanned<V3>, what: &str) -> Result<Vec3> {
        let x = v.get_ref().0;
        if x.cmpge(Vec3::ZERO).all() && x.cmple(Vec3::ONE).all() {
            Ok(x)
        } else {
            Err(self.err(
                v.span(),
                format!("{what}: every colour channel must be between 0 and 1, got {}", fmt_v3(x)),
            ))
        }
    }

    fn unit_vector(&self, v: &Spanned<V3>, what: &str) -> Result<Vec3> {
        normalized(v.get_ref().0.as_dvec3()).ok_or_else(|| {
            self.err(
                v.span(),
                format!("{what}: must not be a zero-length vector, got {}", fmt_v3(v.get_ref().0)),
            )
        })
    }

    fn camera(&self, raw: &Spanned<Table<RawCamera>>) -> Result<Camera> {
        let c = &raw.get_ref().0;
        let mut cam = Camera::default();
        if let Some(p) = &c.position {
            cam.position = p.get_ref().0;
        }
        let mut view_span = raw.span();
        match (&c.look_at, &c.direction) {
            (Some(_), Some(d)) => {
                return Err(self.err(d.span(), "camera: give either `look_at` or `direction`, not both"));
            }
            (Some(l), None) => {
                view_span = l.span();
                let d = l.get_ref().0.as_dvec3() - cam.position.as_dvec3();
                cam.forward = normalized(d).ok_or_else(|| {
                    self.err(
                        l.span(),
                        format!(
                            "camera.look_at: must differ from camera.position, both are {}",
                            fmt_v3(cam.position)
                        ),
                    )
                })?;
            }
            (None, Some(d)) => {
                view_span = d.span();
                cam.forward = self.unit_vector(d, "camera.direction")?;
            }
            (None, None) => {}
        }
        if let Some(u) = &c.up {
            cam.up = self.unit_vector(u, "camera.up")?;
        }
        if cam.forward.as_dvec3().cross(cam.up.as_dvec3()).length() < 1e-6 {
            let (span, what) = match &c.up {
                Some(u) => (u.span(), "camera.up"),
                None => (view_span, "camera"),
            };
            return Err(self.err(
                span,
                format!(
                    "{what}: the up vector {} is parallel to the view direction {}; choose another `up`",
                    fmt_v3(cam.up),
                    fmt_v3(cam.forward)
                ),
            ));
        }
        if let Some(f) = &c.fov {
            let x = f.get_ref().0;
            if !(x > 0.0 && x < 180.0) {
                return Err(self.err(
                    f.span(),
                    format!("camera.fov: must be between 0 and 180 degrees (exclusive), got {x}"),
                ));
            }
            cam.fov_y_deg = x;
        }
        if let Some(w) = &c.width {
            cam.width = self.image_size(w, "camera.width")?;
        }
        if let Some(h) = &c.height {
            cam.height = self.image_size(h, "camera.height")?;
        }
        Ok(cam)
    }

    fn image_size(&self, v: &Spanned<Int>, what: &str) -> Result<u32> {
        let x = v.get_ref().0;
        if (1..=MAX_IMAGE_SIZE as i64).contains(&x) {
            Ok(x as u32)
        } else {
            Err(self.err(v.span(), format!("{what}: must be between 1 and {MAX_IMAGE_SIZE} pixels, got {x}")))
        }
    }

    fn settings(&self, raw: &Spanned<Table<RawSettings>>) -> Result<Settings> {
        let s = &raw.get_ref().0;
        let mut out = Settings::default();
        if let Some(d) = &s.max_depth {
            let x = d.get_ref().0;
            if !(0..=MAX_RECURSION_DEPTH as i64).contains(&x) {
                return Err(self.err(
                    d.span(),
                    format!("settings.max_depth: must be between 0 and {MAX_RECURSION_DEPTH}, got {x}"),
                ));
            }
            out.max_depth = x as u32;
        }
        if let Some(b) = &s.background {
            out.background = self.color(b, "settings.background")?;
        }
        if let Some(m) = &s.max_distance {
            out.max_distance = self.positive(m, "settings.max_distance")?;
        }
        Ok(out)
    }

    fn light(&self, raw: &Spanned<Table<RawLight>>, at: &str) -> Result<Light> {
        let l = &raw.get_ref().0;
        let ty = l.kind.get_ref().as_str();
        let Some(allowed) = light_type_keys(ty) else {
            return Err(self.err(
                l.kind.span(),
                format!("{at}.type: unknown light type `{ty}`; valid types: {}", LIGHT_TYPES.join(", ")),
            ));
        };
        for (key, span) in l.specific_keys() {
            if !allowed.contains(&key) {
                return Err(self.err(
                    span,
                    format!(
                        "{at}: key `{key}` is not valid for {} {ty} light; valid keys: type, {}",
                        article(ty),
                        allowed.join(", ")
                    ),
                ));
            }
        }
        let missing =
            |key: &str| self.err(l.kind.span(), format!("{at}: {} {ty} light needs `{key}`", article(ty)));
        let intensity = match &l.intensity {
            Some(i) => self.non_negative(i, &format!("{at}.intensity"))?,
            None => return Err(missing("intensity")),
        };
        let color = match &l.color {
            Some(c) => self.color(c, &format!("{at}.color"))?,
            None => Vec3::ONE,
        };
        Ok(match ty {
            "ambient" => Light::Ambient { intensity },
            "point" => Light::Point {
                position: l.position.as_ref().ok_or_else(|| missing("position"))?.get_ref().0,
                intensity,
                color,
            },
            _ => {
                let d = l.direction.as_ref().ok_or_else(|| missing("direction"))?;
                Light::Directional {
                    direction: self.unit_vector(d, &format!("{at}.direction"))?,
                    intensity,
                    color,
                }
            }
        })
    }

    fn material(&self, name: &str, raw: &Spanned<Table<RawMaterial>>) -> Result<Material> {
        let m = &raw.get_ref().0;
        let at = format!("materials.{}", key_text(name));
        let w = |key: &str| format!("{at}.{key}");
        let mut out = Material {
            name: name.to_string(),
            color: self.color(&m.color, &w("color"))?,
            ..Material::default()
        };
        if let Some(v) = &m.ka {
            out.ka = self.non_negative(v, &w("ka"))?;
        }
        if let Some(v) = &m.kd {
            out.kd = self.non_negative(v, &w("kd"))?;
        }
        if let Some(v) = &m.ks {
            out.ks = self.non_negative(v, &w("ks"))?;
        }
        if let Some(v) = &m.shininess {
            out.shininess = Some(self.positive(v, &w("shininess"))?);
        }
        if let Some(v) = &m.reflectivity {
            out.reflectivity = self.unit_interval(v, &w("reflectivity"))?;
        }
        if let Some(v) = &m.transparency {
            out.transparency = self.unit_interval(v, &w("transparency"))?;
        }
        if let Some(v) = &m.ior {
            out.ior = self.positive(v, &w("ior"))?;
        }
        Ok(out)
    }

    /// Converts one object table (and its subtree). `at` is its key path; `inherited` the
    /// material of the nearest ancestor that names one.
    fn object(
        &self,
        o: &RawObject,
        at: &str,
        inherited: Option<MaterialId>,
        materials: &mut Materials,
    ) -> Result<Object> {
        let ty = o.kind.get_ref().as_str();
        let Some(allowed) = object_type_keys(ty) else {
            return Err(self.err(
                o.kind.span(),
                format!("{at}.type: unknown object type `{ty}`; valid types: {}", OBJECT_TYPES.join(", ")),
            ));
        };
        for (key, span) in o.specific_keys() {
            if !allowed.contains(&key) {
                return Err(self.err(
                    span,
                    format!(
                        "{at}: key `{key}` is not valid for {} {ty}; valid keys: {}, {}",
                        article(ty),
                        OBJECT_COMMON_KEYS.join(", "),
                        allowed.join(", ")
                    ),
                ));
            }
        }
        let w = |key: &str| format!("{at}.{key}");
        let type_span = o.kind.span();
        let missing =
            |key: &str| self.err(type_span.clone(), format!("{at}: {} {ty} needs `{key}`", article(ty)));
        let req_num = |v, key| need(v, &missing, key);
        let req_v3 = |v, key| need(v, &missing, key);
        let req_str = |v, key| need(v, &missing, key);

        let own_material = match &o.material {
            Some(name) => Some(*materials.by_name.get(name.get_ref()).ok_or_else(|| {
                let mut known: Vec<_> = materials.by_name.keys().map(String::as_str).collect();
                known.sort_unstable();
                let known = if known.is_empty() {
                    "none are defined".to_string()
                } else {
                    format!("defined: {}", known.join(", "))
                };
                self.err(
                    name.span(),
                    format!("{}: unknown material `{}` ({known})", w("material"), name.get_ref()),
                )
            })?),
            None => None,
        };
        let material = own_material.or(inherited);

        let mut transform = TransformDesc::default();
        if let Some(t) = &o.translate {
            transform.translate = t.get_ref().0;
        }
        if let Some(r) = &o.rotate {
            transform.rotate_deg = r.get_ref().0;
        }
        if let Some(s) = &o.scale {
            let v = match *s.get_ref() {
                Scale::Uniform(x) => Vec3::splat(x),
                Scale::PerAxis(v) => v,
            };
            if !v.cmpgt(Vec3::ZERO).all() {
                let got = match *s.get_ref() {
                    Scale::Uniform(x) => x.to_string(),
                    Scale::PerAxis(v) => fmt_v3(v),
                };
                return Err(
                    self.err(s.span(), format!("{}: every scale factor must be > 0, got {got}", w("scale")))
                );
            }
            transform.scale = v;
        }

        let label = match &o.name {
            Some(n) => n.get_ref().clone(),
            None => at.to_string(),
        };

        let primitive = match ty {
            "sphere" => Some(Primitive::Sphere {
                radius: self.positive(req_num(&o.radius, "radius")?, &w("radius"))?,
            }),
            "plane" => {
                let normal = match &o.normal {
                    Some(n) => self.unit_vector(n, &w("normal"))?,
                    None => Vec3::Y,
                };
                let offset = match (&o.offset, &o.point) {
                    (Some(_), Some(p)) => {
                        return Err(
                            self.err(p.span(), format!("{at}: give either `offset` or `point`, not both"))
                        );
                    }
                    (Some(d), None) => d.get_ref().0,
                    (None, Some(p)) => normal.dot(p.get_ref().0),
                    (None, None) => 0.0,
                };
                Some(Primitive::Plane { normal, offset })
            }
            "box" => Some(Primitive::Box {
                half: self.positive3(req_v3(&o.half_size, "half_size")?, &w("half_size"))?,
            }),
            "ellipsoid" => {
                Some(Primitive::Ellipsoid { radii: self.positive3(req_v3(&o.radii, "radii")?, &w("radii"))? })
            }
            "cylinder" => Some(Primitive::Cylinder {
                radius: self.positive(req_num(&o.radius, "radius")?, &w("radius"))?,
                half_height: 0.5 * self.positive(req_num(&o.height, "height")?, &w("height"))?,
            }),
            "cone" => {
                let bottom = req_num(&o.radius_bottom, "radius_bottom")?;
                let radius_bottom = self.non_negative(bottom, &w("radius_bottom"))?;
                let radius_top = match &o.radius_top {
                    Some(t) => self.non_negative(t, &w("radius_top"))?,
                    None => 0.0,
                };
                if radius_bottom == 0.0 && radius_top == 0.0 {
                    return Err(self.err(
                        bottom.span(),
                        format!("{at}: `radius_bottom` and `radius_top` must not both be 0"),
                    ));
                }
                Some(Primitive::Cone {
                    radius_bottom,
                    radius_top,
                    half_height: 0.5 * self.positive(req_num(&o.height, "height")?, &w("height"))?,
                })
            }
            "torus" => Some(Primitive::Torus {
                major: self.positive(req_num(&o.major_radius, "major_radius")?, &w("major_radius"))?,
                minor: self.positive(req_num(&o.minor_radius, "minor_radius")?, &w("minor_radius"))?,
            }),
            "triangle" => {
                let a = req_v3(&o.a, "a")?.get_ref().0;
                let b = req_v3(&o.b, "b")?.get_ref().0;
                let c = req_v3(&o.c, "c")?;
                let (e1, e2) = (b.as_dvec3() - a.as_dvec3(), c.get_ref().0.as_dvec3() - a.as_dvec3());
                if e1.cross(e2).length() <= 1e-6 * e1.length() * e2.length() {
                    return Err(self.err(
                        c.span(),
                        format!(
                            "{at}: the triangle's vertices {}, {} and {} are collinear",
                            fmt_v3(a),
                            fmt_v3(b),
                            fmt_v3(c.get_ref().0)
                        ),
                    ));
                }
                Some(Primitive::Triangle { a, b, c: c.get_ref().0 })
            }
            "capsule" => Some(Primitive::Capsule {
                a: req_v3(&o.a, "a")?.get_ref().0,
                b: req_v3(&o.b, "b")?.get_ref().0,
                radius: self.positive(req_num(&o.radius, "radius")?, &w("radius"))?,
            }),
            _ => None,
        };
        if let Some(p) = primitive {
            let material = material.unwrap_or_else(|| materials.default_id());
            return Ok(Object { kind: ObjectKind::Primitive(p), transform, material, label });
        }

        if ty == "mesh" {
            let file = req_str(&o.path, "path")?;
            if at.contains(".child") {
                return Err(self.err(
                    o.kind.span(),
                    format!(
                        "{at}: a mesh can only be a top-level object (meshes have no analytic SDF for CSG)"
                    ),
                ));
            }
            let shading = match o.shading.as_ref().map(|s| (s.get_ref().as_str(), s.span())) {
                None | Some(("flat", _)) => Shading::Flat,
                Some(("smooth", _)) => Shading::Smooth,
                Some((other, span)) => {
                    return Err(self.err(
                        span,
                        format!("{}: must be \"flat\" or \"smooth\", got \"{other}\"", w("shading")),
                    ));
                }
            };
            // Relative to the scene file's folder.
            let source = self.path.parent().unwrap_or(Path::new("")).join(file.get_ref());
            let (mesh, _report) = crate::mesh::load_mesh(&source)?;
            let material = material.unwrap_or_else(|| materials.default_id());
            return Ok(Object {
                kind: ObjectKind::Mesh { mesh: Arc::new(mesh), source, shading },
                transform,
                material,
                label,
            });
        }

        if ty == "grid" {
            let file = req_str(&o.path, "path")?;
            if at.contains(".child") {
                return Err(self.err(
                    o.kind.span(),
                    format!(
                        "{at}: a grid can only be a top-level object (grid files do not take part in CSG)"
                    ),
                ));
            }
            if let Some(sc) = &o.scale
                && !Transform::new(&transform).is_uniform()
            {
                return Err(self.err(
                    sc.span(),
                    format!(
                        "{}: a grid's scale must be the same on every axis (its samples are distances)",
                        w("scale")
                    ),
                ));
            }
            // Relative to the scene file's folder.
            let source = self.path.parent().unwrap_or(Path::new("")).join(file.get_ref());
            let grid = crate::grid::io::load_grid(&source)?;
            let material = material.unwrap_or_else(|| materials.default_id());
            return Ok(Object {
                kind: ObjectKind::Grid { grid: Arc::new(grid), source },
                transform,
                material,
                label,
            });
        }

        if ty == "implicit" {
            let file = req_str(&o.path, "path")?;
            if at.contains(".child") {
                return Err(self.err(
                    o.kind.span(),
                    format!(
                        "{at}: an implicit model can only be a top-level object (it takes no part in CSG)"
                    ),
                ));
            }
            // Relative to the scene file's folder.
            let source = self.path.parent().unwrap_or(Path::new("")).join(file.get_ref());
            let field = crate::implicit::load_field(&source)?;
            let material = material.unwrap_or_else(|| materials.default_id());
            return Ok(Object { kind: ObjectKind::Implicit { field, source }, transform, material, label });
        }

        let kind = if ty == "repeat" {
            let period = req_v3(&o.period, "period")?;
            let pv = period.get_ref().0;
            if !pv.cmpge(Vec3::ZERO).all() || !pv.cmpgt(Vec3::ZERO).any() {
                return Err(self.err(
                    period.span(),
                    format!(
                        "{}: every component must be >= 0 and at least one > 0, got {}",
                        w("period"),
                        fmt_v3(pv)
                    ),
                ));
            }
            let count = match &o.count {
                Some(c) => {
                    let v = c.get_ref().0;
                    if !v.iter().all(|&n| (1..=u32::MAX as i64).contains(&n)) {
                        return Err(self.err(
                            c.span(),
                            format!(
                                "{}: every count must be an integer >= 1, got [{}, {}, {}]",
                                w("count"),
                                v[0],
                                v[1],
                                v[2]
                            ),
                        ));
                    }
                    Some(UVec3::new(v[0] as u32, v[1] as u32, v[2] as u32))
                }
                None => None,
            };
            let Some(child) = &o.child else {
                return Err(missing("child"));
            };
            let child = self.object(&child.get_ref().0, &w("child"), material, materials)?;
            ObjectKind::Repeat { period: pv, count, child: Box::new(child) }
        } else {
            let op = match ty {
                "union" => CsgOp::Union,
                "subtraction" => CsgOp::Subtraction,
                "intersection" => CsgOp::Intersection,
                smooth => {
                    let k = self.positive(req_num(&o.blend, "blend")?, &w("blend"))?;
                    match smooth {
                        "smooth_union" => CsgOp::SmoothUnion { k },
                        "smooth_subtraction" => CsgOp::SmoothSubtraction { k },
                        _ => CsgOp::SmoothIntersection { k },
                    }
                }
            };
            let Some(children) = &o.children else {
                return Err(missing("children"));
            };
            let needed = if ty.ends_with("subtraction") { 2 } else { 1 };
            let n = children.get_ref().len();
            if n < needed {
                return Err(self.err(
                    children.span(),
                    format!(
                        "{}: {} {ty} needs at least {needed} child{}, got {n}",
                        w("children"),
                        article(ty),
                        if needed == 1 { "" } else { "ren" }
                    ),
                ));
            }
            let mut out = Vec::with_capacity(n);
            for (i, c) in children.get_ref().iter().enumerate() {
                out.push(self.object(&c.get_ref().0, &format!("{at}.children[{i}]"), material, materials)?);
            }
            ObjectKind::Csg { op, children: out }
        };
        // A CSG or repeat node without its own or an inherited material takes its first
        // child's (the surfaces are coloured by the leaves).
        let material = material.unwrap_or(match &kind {
            ObjectKind::Csg { children, .. } => children[0].material,
            ObjectKind::Repeat { child, .. } => child.material,
            ObjectKind::Primitive(_)
            | ObjectKind::Mesh { .. }
            | ObjectKind::Grid { .. }
            | ObjectKind::Implicit { .. } => {
                unreachable!("primitives, meshes, grids and implicit models returned above")
            }
        });
        Ok(Object { kind, transform, material, label })
    }
}

// ---------------------------------------------------------------------------------------
// Helpers.

/// The value of a required key, or the "needs `key`" error.
fn need<'r, T>(
    v: &'r Option<Spanned<T>>,
    missing: &dyn Fn(&str) -> Error,
    key: &str,
) -> Result<&'r Spanned<T>> {
    v.as_ref().ok_or_else(|| missing(key))
}

/// `v` scaled to unit length, or `None` when it is zero (or not finite).
fn normalized(v: DVec3) -> Option<Vec3> {
    let len = v.length();
    (len > 0.0 && len.is_finite()).then(|| (v / len).as_vec3())
}

/// "a" or "an" for a type name.
fn article(word: &str) -> &'static str {
    match word.as_bytes().first() {
        Some(b'a' | b'e' | b'i' | b'o') => "an",
        _ => "a",
    }
}

fn fmt_v3(v: Vec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

/// A table key as it would be written in TOML (quoted unless it is a bare key).
fn key_text(key: &str) -> String {
    let bare = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare { key.to_string() } else { format!("{key:?}") }
}

/// The 1-based line and column (in characters) of byte offset `offset` in `text`.
fn location(text: &str, offset: usize) -> Location {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    Location { line: before.matches('\n').count() + 1, column: before[line_start..].chars().count() + 1 }
}

// ---------------------------------------------------------------------------------------
// serde errors: locate the key path of the offending span and reword the message.

/// One step of a key path.
#[derive(Clone)]
enum Seg {
    Key(String),
    Index(usize),
}

fn fmt_path(segs: &[Seg]) -> String {
    let mut out = String::new();
    for s in segs {
        match s {
            Seg::Key(k) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(&key_text(k));
            }
            Seg::Index(i) => out.push_str(&format!("[{i}]")),
        }
    }
    out
}

/// The smallest key or value whose span contains the target span (ties go to the deeper).
#[derive(Clone)]
struct Hit {
    segs: Vec<Seg>,
    is_key: bool,
    len: usize,
}

struct Finder {
    target: Range<usize>,
    path: Vec<Seg>,
    best: Option<Hit>,
}

impl Finder {
    fn consider(&mut self, span: Range<usize>, is_key: bool) {
        if span.start <= self.target.start && self.target.end <= span.end {
            let len = span.end - span.start;
            let better = self
                .best
                .as_ref()
                .is_none_or(|b| len < b.len || (len == b.len && self.path.len() >= b.segs.len()));
            if better {
                self.best = Some(Hit { segs: self.path.clone(), is_key, len });
            }
        }
    }

    fn table(&mut self, t: &DeTable<'_>) {
        for (k, v) in t.iter() {
            self.path.push(Seg::Key(k.get_ref().to_string()));
            self.consider(k.span(), true);
            self.value(v);
            self.path.pop();
        }
    }

    fn value(&mut self, v: &Spanned<DeValue<'_>>) {
        self.consider(v.span(), false);
        match v.get_ref() {
            DeValue::Table(t) => self.table(t),
            DeValue::Array(a) => {
                for (i, e) in a.iter().enumerate() {
                    self.path.push(Seg::Index(i));
                    self.value(e);
                    self.path.pop();
                }
            }
            _ => {}
        }
    }
}

/// Where `span` is in the document `tree`.
fn locate(tree: &DeTable<'_>, span: Range<usize>) -> Option<Hit> {
    let mut f = Finder { target: span, path: Vec::new(), best: None };
    f.table(tree);
    f.best
}

/// The table at `segs` in `tree`.
fn table_at<'a, 'i>(tree: &'a DeTable<'i>, segs: &[Seg]) -> Option<&'a DeTable<'i>> {
    let mut value: Option<&DeValue<'i>> = None;
    let mut table = tree;
    for s in segs {
        let v = match (s, value) {
            (Seg::Key(k), None) => table.get(k.as_str())?.get_ref(),
            (Seg::Key(k), Some(DeValue::Table(t))) => t.get(k.as_str())?.get_ref(),
            (Seg::Index(i), Some(DeValue::Array(a))) => a.get(*i)?.get_ref(),
            _ => return None,
        };
        value = Some(v);
        if let DeValue::Table(t) = v {
            table = t;
            value = None;
        }
    }
    if value.is_none() { Some(table) } else { None }
}

/// The valid keys of the object or light table at `segs`, when its `type` is known.
fn typed_table_keys(tree: &DeTable<'_>, segs: &[Seg]) -> Option<String> {
    let Some(Seg::Key(root)) = segs.first() else {
        return None;
    };
    let table = table_at(tree, segs)?;
    let ty = table.get("type")?.get_ref().as_str()?;
    match root.as_str() {
        "objects" => {
            let keys = object_type_keys(ty)?;
            Some(format!(
                "valid keys for {} {ty}: {}, {}",
                article(ty),
                OBJECT_COMMON_KEYS.join(", "),
                keys.join(", ")
            ))
        }
        "lights" => {
            let keys = light_type_keys(ty)?;
            Some(format!("valid keys for {} {ty} light: type, {}", article(ty), keys.join(", ")))
        }
        _ => None,
    }
}

/// Turns a serde/TOML error into a one-line input error with the key path.
fn translate_de_error(text: &str, path: &Path, e: &toml::de::Error) -> Error {
    let msg = e
        .message()
        .trim()
        .replace('\n', " ")
        .replace("expected a sequence", "expected an array")
        .replace("invalid type: sequence", "invalid type: array")
        .replace("invalid type: map", "invalid type: table")
        .replace("expected a map", "expected a table");
    let Some(span) = e.span() else {
        return Error::input(path, None, msg);
    };
    let loc = Some(location(text, span.start));
    let tree = match DeTable::parse(text) {
        Ok(t) => t.into_inner(),
        Err(_) => return Error::input(path, loc, format!("invalid TOML: {msg}")),
    };
    let (mut segs, is_key) = match locate(&tree, span) {
        Some(h) => (h.segs, h.is_key),
        None => (Vec::new(), false),
    };
    if msg.starts_with("expected a single table") && matches!(segs.last(), Some(Seg::Index(_))) {
        // `[[a.b]]` where `[a.b]` is meant: name the key, not its first element.
        segs.pop();
    }
    let prefix = |segs: &[Seg]| {
        if segs.is_empty() { String::new() } else { format!("{}: ", fmt_path(segs)) }
    };
    if let Some((name, expected)) = msg.strip_prefix("unknown field `").and_then(|rest| rest.split_once('`'))
    {
        let parent = if is_key { &segs[..segs.len().saturating_sub(1)] } else { &segs[..] };
        let valid = typed_table_keys(&tree, parent).unwrap_or_else(|| {
            expected
                .trim_start_matches(',')
                .trim()
                .replace("expected one of", "valid keys:")
                .replace("expected", "valid keys:")
                .replace('`', "")
        });
        return Error::input(path, loc, format!("{}unknown key `{name}`; {valid}", prefix(parent)));
    }
    if let Some(rest) = msg.strip_prefix("missing field `") {
        let name = rest.split('`').next().unwrap_or(rest);
        return Error::input(path, loc, format!("{}missing key `{name}`", prefix(&segs)));
    }
    Error::input(path, loc, format!("{}{msg}", prefix(&segs)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_scene_in_data_parses() {
        // data/scenes and its generated families one folder down (tools/gen-scenes).
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes");
        let mut count = 0;
        let mut folders = vec![dir.clone()];
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(&folder).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    folders.push(path);
                } else if path.extension().is_some_and(|e| e == "toml") {
                    let scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
                    assert!(!scene.objects.is_empty(), "{}", path.display());
                    assert!(!scene.lights.is_empty(), "{}", path.display());
                    count += 1;
                }
            }
        }
        assert!(count >= 40, "only {count} scenes in {}", dir.display());
    }

    #[test]
    fn documented_example_parses() {
        let doc = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/scene-format.md"))
            .unwrap();
        let example = doc
            .split("## Complete example")
            .nth(1)
            .and_then(|rest| rest.split("```toml\n").nth(1))
            .and_then(|block| block.split("```").next())
            .expect("docs/scene-format.md has a complete example");
        let scene = parse_scene(example, Path::new("scene-format.md")).unwrap_or_else(|e| panic!("{e}"));
        // Every object type except the CSG-only ones appears at the top level.
        assert!(scene.objects.len() >= 12);
        assert_eq!(scene.lights.len(), 3);
        // The sphere without a material uses the appended default.
        assert_eq!(scene.materials.last().unwrap().name, "default");
    }
}

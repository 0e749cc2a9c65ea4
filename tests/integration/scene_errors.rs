//! The scene file format through the public API: every kind of bad input gives one
//! `file:line:column: message` error with exit code 2, and a complete valid scene turns
//! into the expected `Scene` values.

use std::path::Path;

use glam::{UVec3, Vec3};
use sdfmesh::error::Error;
use sdfmesh::scene::shape::{CsgOp, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;
use sdfmesh::scene::{Camera, Light, Material, Settings, load_scene, parse_scene};

/// Parses `text` as `bad.toml` and checks that it fails at `line:column` with a message
/// containing `needle`, on one line, with exit code 2.
#[track_caller]
fn fails(text: &str, line: usize, column: usize, needle: &str) {
    let err = match parse_scene(text, Path::new("bad.toml")) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e,
    };
    assert_eq!(err.exit_code(), 2, "{err}");
    assert!(matches!(err, Error::Input { .. }), "{err:?}");
    let msg = err.to_string();
    let prefix = format!("bad.toml:{line}:{column}: ");
    assert!(msg.starts_with(&prefix), "expected prefix {prefix:?}, got {msg:?}");
    assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
    assert!(!msg.contains('\n'), "not one line: {msg:?}");
}

fn ok(text: &str) -> sdfmesh::scene::Scene {
    parse_scene(text, Path::new("good.toml")).unwrap_or_else(|e| panic!("{e}"))
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-6
}

// --- syntax, unknown keys, wrong types ------------------------------------------------

#[test]
fn toml_syntax_errors() {
    fails("[camera\n", 1, 8, "invalid TOML");
    fails("[camera]\nfov = 1\nfov = 2\n", 3, 1, "invalid TOML: duplicate key");
    fails("[camera]\nfov = \n", 2, 7, "invalid TOML");
}

#[test]
fn unknown_keys() {
    fails("bogus = 1\n", 1, 1, "unknown key `bogus`; valid keys: camera, settings");
    fails("[camera]\nfoo = 1\n", 2, 1, "camera: unknown key `foo`; valid keys: position, look_at, direction");
    fails("[settings]\n\ndepth = 3\n", 3, 1, "settings: unknown key `depth`");
    fails(
        "[[lights]]\ntype = 'ambient'\nintensity = 1\nfoo = 1\n",
        4,
        1,
        "lights[0]: unknown key `foo`; valid keys for an ambient light: type, intensity",
    );
    fails(
        "[materials.red]\ncolor = [1, 0, 0]\nglow = 0\n",
        3,
        1,
        "materials.red: unknown key `glow`; valid keys: color, ka, kd",
    );
    fails(
        "[[objects]]\ntype = 'box'\nwobble = 1\n",
        3,
        1,
        "objects[0]: unknown key `wobble`; valid keys for a box: type, name, material, translate, rotate, scale, half_size",
    );
    // In nested children, as array-of-tables and as inline tables.
    fails(
        "[[objects]]\ntype = 'union'\n[[objects.children]]\ntype = 'sphere'\nbogus = 0\n",
        5,
        1,
        "objects[0].children[0]: unknown key `bogus`; valid keys for a sphere",
    );
    fails(
        "[[objects]]\ntype = 'union'\nchildren = [{ type = 'sphere', radius = 1, bogus = 2 }]\n",
        3,
        44,
        "objects[0].children[0]: unknown key `bogus`",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\n[objects.child]\ntype = 'sphere'\nradius = 1\nx = 1\n",
        7,
        1,
        "objects[0].child: unknown key `x`",
    );
}

#[test]
fn keys_not_valid_for_the_type() {
    fails(
        "[[objects]]\ntype = 'box'\nradius = 1\n",
        3,
        10,
        "objects[0]: key `radius` is not valid for a box; valid keys: type, name, material, translate, rotate, scale, half_size",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\nchildren = []\n",
        4,
        12,
        "key `children` is not valid for a repeat",
    );
    fails(
        "[[objects]]\ntype = 'union'\nblend = 1\nchildren = [{ type = 'sphere', radius = 1 }]\n",
        3,
        9,
        "key `blend` is not valid for a union",
    );
    fails(
        "[[lights]]\ntype = 'ambient'\nintensity = 1\ncolor = [1, 1, 1]\n",
        4,
        9,
        "lights[0]: key `color` is not valid for an ambient light",
    );
    fails(
        "[[lights]]\ntype = 'point'\nintensity = 1\nposition = [0, 0, 0]\ndirection = [0, 0, 1]\n",
        5,
        13,
        "key `direction` is not valid for a point light",
    );
}

#[test]
fn wrong_types() {
    fails("[camera]\nfov = 'wide'\n", 2, 7, "camera.fov: invalid type: string \"wide\", expected a number");
    fails(
        "[camera]\nwidth = 1.5\n",
        2,
        9,
        "camera.width: invalid type: floating point `1.5`, expected an integer",
    );
    fails(
        "[camera]\nposition = [1, 2, 'x']\n",
        2,
        19,
        "camera.position[2]: invalid type: string \"x\", expected a number",
    );
    fails("camera = 5\n", 1, 10, "camera: invalid type: integer `5`, expected a table");
    fails("[[camera]]\nfov = 60\n", 1, 1, "camera: expected a single table, got an array");
    fails("objects = 3\n", 1, 11, "objects: invalid type: integer `3`, expected an array");
    fails("[objects]\ntype = 'sphere'\n", 1, 1, "objects: invalid type: table, expected an array");
    fails("[materials]\nred = 3\n", 2, 7, "materials.red: invalid type: integer `3`, expected a table");
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\nname = 3\n",
        4,
        8,
        "objects[0].name: invalid type: integer `3`, expected a string",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = [1, 2, 3]\n",
        3,
        10,
        "objects[0].radius: invalid type: array, expected a number",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\nscale = 'big'\n",
        4,
        9,
        "objects[0].scale: invalid type: string \"big\", expected a number or an array of 3 numbers",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\nmaterial = 1\n",
        4,
        12,
        "objects[0].material: invalid type: integer `1`, expected a string",
    );
    fails("[[objects]]\ntype = 3\n", 2, 8, "objects[0].type: invalid type: integer `3`, expected a string");
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\n[[objects.child]]\ntype = 'sphere'\nradius = 1\n",
        4,
        1,
        "objects[0].child: expected a single table, got an array",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\ncount = [1.5, 1, 1]\n",
        4,
        10,
        "objects[0].count[0]: invalid type: floating point `1.5`, expected an integer",
    );
}

#[test]
fn vectors_need_three_components() {
    fails(
        "[camera]\nposition = [1, 2]\n",
        2,
        12,
        "camera.position: expected an array of 3 numbers [x, y, z], got 2 elements",
    );
    fails(
        "[camera]\nposition = [1, 2, 3, 4]\n",
        2,
        12,
        "camera.position: expected an array of 3 numbers [x, y, z], got 4 elements",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\ncount = [1, 1]\n",
        4,
        9,
        "objects[0].count: expected an array of 3 integers",
    );
}

#[test]
fn missing_required_keys() {
    fails("[[lights]]\nintensity = 1\n", 1, 1, "lights[0]: missing key `type`");
    fails("[[lights]]\ntype = 'ambient'\n", 2, 8, "lights[0]: an ambient light needs `intensity`");
    fails("[[lights]]\ntype = 'point'\nintensity = 1\n", 2, 8, "a point light needs `position`");
    fails("[[lights]]\ntype = 'directional'\nintensity = 1\n", 2, 8, "a directional light needs `direction`");
    fails("[materials.red]\nka = 1\n", 1, 1, "materials.red: missing key `color`");
    fails("[[objects]]\nradius = 1\n", 1, 1, "objects[0]: missing key `type`");
    fails(
        "[[objects]]\ntype = 'union'\nchildren = [{ radius = 1 }]\n",
        3,
        13,
        "objects[0].children[0]: missing key `type`",
    );
    fails("[[objects]]\ntype = 'sphere'\n", 2, 8, "objects[0]: a sphere needs `radius`");
    fails("[[objects]]\ntype = 'box'\n", 2, 8, "a box needs `half_size`");
    fails("[[objects]]\ntype = 'ellipsoid'\n", 2, 8, "an ellipsoid needs `radii`");
    fails("[[objects]]\ntype = 'cylinder'\nradius = 1\n", 2, 8, "a cylinder needs `height`");
    fails("[[objects]]\ntype = 'cone'\nheight = 1\n", 2, 8, "a cone needs `radius_bottom`");
    fails("[[objects]]\ntype = 'torus'\nmajor_radius = 1\n", 2, 8, "a torus needs `minor_radius`");
    fails("[[objects]]\ntype = 'triangle'\na = [0, 0, 0]\nb = [1, 0, 0]\n", 2, 8, "a triangle needs `c`");
    fails("[[objects]]\ntype = 'capsule'\na = [0, 0, 0]\nradius = 1\n", 2, 8, "a capsule needs `b`");
    fails("[[objects]]\ntype = 'union'\n", 2, 8, "objects[0]: a union needs `children`");
    fails(
        "[[objects]]\ntype = 'smooth_union'\nchildren = [{ type = 'sphere', radius = 1 }]\n",
        2,
        8,
        "objects[0]: a smooth_union needs `blend`",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nchild = { type = 'sphere', radius = 1 }\n",
        2,
        8,
        "a repeat needs `period`",
    );
    fails("[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\n", 2, 8, "objects[0]: a repeat needs `child`");
}

#[test]
fn unknown_types() {
    fails(
        "[[objects]]\ntype = 'blob'\n",
        2,
        8,
        "objects[0].type: unknown object type `blob`; valid types: sphere, plane, box, ellipsoid, cylinder, cone, torus, triangle, capsule, union, subtraction, intersection, smooth_union, smooth_subtraction, smooth_intersection, repeat, mesh",
    );
    fails(
        "[[objects]]\ntype = 'union'\n\n[[objects.children]]\ntype = 'Sphere'\n",
        5,
        8,
        "objects[0].children[0].type: unknown object type `Sphere`",
    );
    fails(
        "[[lights]]\ntype = 'spot'\n",
        2,
        8,
        "lights[0].type: unknown light type `spot`; valid types: ambient, point, directional",
    );
}

// --- values out of range --------------------------------------------------------------

#[test]
fn non_finite_numbers_are_rejected_everywhere() {
    fails("[camera]\nfov = nan\n", 2, 7, "camera.fov: must be a finite number, got nan");
    fails("[camera]\nfov = -inf\n", 2, 7, "camera.fov: must be a finite number, got -inf");
    fails(
        "[camera]\nposition = [0, inf, 0]\n",
        2,
        16,
        "camera.position[1]: must be a finite number, got inf",
    );
    fails("[settings]\nmax_distance = inf\n", 2, 16, "settings.max_distance: must be a finite number");
    fails(
        "[[lights]]\ntype = 'ambient'\nintensity = +inf\n",
        3,
        13,
        "lights[0].intensity: must be a finite number",
    );
    fails(
        "[materials.m]\ncolor = [nan, 0, 0]\n",
        2,
        10,
        "materials.m.color[0]: must be a finite number, got nan",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = nan\n",
        3,
        10,
        "objects[0].radius: must be a finite number, got nan",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\nscale = inf\n",
        4,
        9,
        "objects[0].scale: must be a finite number",
    );
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\ntranslate = [1, 2, -nan]\n",
        4,
        20,
        "objects[0].translate[2]: must be a finite number",
    );
    // Finite in TOML but not in single precision.
    fails("[camera]\nfov = 1e39\n", 2, 7, "camera.fov: 1e39 is out of range");
}

#[test]
fn camera_values() {
    fails(
        "[camera]\nlook_at = [0, 0, 1]\ndirection = [0, 0, 1]\n",
        3,
        13,
        "camera: give either `look_at` or `direction`, not both",
    );
    fails(
        "[camera]\nposition = [1, 1, 1]\nlook_at = [1, 1, 1]\n",
        3,
        11,
        "camera.look_at: must differ from camera.position",
    );
    fails(
        "[camera]\ndirection = [0, 0, 0]\n",
        2,
        13,
        "camera.direction: must not be a zero-length vector, got [0, 0, 0]",
    );
    fails("[camera]\nup = [0, 0, 0]\n", 2, 6, "camera.up: must not be a zero-length vector");
    fails(
        "[camera]\nup = [0, 0, 2]\n",
        2,
        6,
        "camera.up: the up vector [0, 0, 1] is parallel to the view direction [0, 0, 1]",
    );
    // The default up [0, 1, 0] with a vertical view direction.
    fails(
        "[camera]\nposition = [0, 5, 0]\nlook_at = [0, 0, 0]\n",
        3,
        11,
        "camera: the up vector [0, 1, 0] is parallel to the view direction [0, -1, 0]",
    );
    fails("[camera]\nfov = 0\n", 2, 7, "camera.fov: must be between 0 and 180 degrees (exclusive), got 0");
    fails(
        "[camera]\nfov = 180\n",
        2,
        7,
        "camera.fov: must be between 0 and 180 degrees (exclusive), got 180",
    );
    fails("[camera]\nfov = -30\n", 2, 7, "got -30");
    fails("[camera]\nwidth = 0\n", 2, 9, "camera.width: must be between 1 and 16384 pixels, got 0");
    fails(
        "[camera]\nheight = 16385\n",
        2,
        10,
        "camera.height: must be between 1 and 16384 pixels, got 16385",
    );
    fails("[camera]\nwidth = -5\n", 2, 9, "camera.width: must be between 1 and 16384 pixels, got -5");
}

#[test]
fn settings_values() {
    fails("[settings]\nmax_depth = -1\n", 2, 13, "settings.max_depth: must be between 0 and 100, got -1");
    fails(
        "[settings]\nmax_depth = 2.5\n",
        2,
        13,
        "settings.max_depth: invalid type: floating point `2.5`, expected an integer",
    );
    fails(
        "[settings]\nbackground = [2, 0, 0]\n",
        2,
        14,
        "settings.background: every colour channel must be between 0 and 1, got [2, 0, 0]",
    );
    fails("[settings]\nmax_distance = 0\n", 2, 16, "settings.max_distance: must be > 0, got 0");
}

#[test]
fn light_values() {
    fails(
        "[[lights]]\ntype = 'ambient'\nintensity = -1\n",
        3,
        13,
        "lights[0].intensity: must be >= 0, got -1",
    );
    fails(
        "[[lights]]\ntype = 'directional'\nintensity = 1\ndirection = [0, 0, 0]\n",
        4,
        13,
        "lights[0].direction: must not be a zero-length vector",
    );
    fails(
        "[[lights]]\ntype = 'ambient'\nintensity = 1\n\n[[lights]]\ntype = 'point'\nposition = [0, 0, 0]\nintensity = 1\ncolor = [1, 1.5, 1]\n",
        9,
        9,
        "lights[1].color: every colour channel must be between 0 and 1, got [1, 1.5, 1]",
    );
}

#[test]
fn material_values() {
    let m = |line: &str| format!("[materials.red]\ncolor = [1, 0, 0]\n{line}\n");
    fails(&m("reflectivity = 1.5"), 3, 16, "materials.red.reflectivity: must be between 0 and 1, got 1.5");
    fails(&m("reflectivity = -0.5"), 3, 16, "materials.red.reflectivity: must be between 0 and 1, got -0.5");
    fails(&m("transparency = -0.1"), 3, 16, "materials.red.transparency: must be between 0 and 1, got -0.1");
    fails(&m("transparency = 2"), 3, 16, "materials.red.transparency: must be between 0 and 1, got 2");
    fails(&m("ior = 0"), 3, 7, "materials.red.ior: must be > 0, got 0");
    fails(&m("shininess = 0"), 3, 13, "materials.red.shininess: must be > 0, got 0");
    fails(&m("ka = -1"), 3, 6, "materials.red.ka: must be >= 0, got -1");
    fails(&m("kd = -1"), 3, 6, "materials.red.kd: must be >= 0, got -1");
    fails(&m("ks = -1"), 3, 6, "materials.red.ks: must be >= 0, got -1");
    fails(
        "[materials.red]\ncolor = [1, 0, -0.5]\n",
        2,
        9,
        "materials.red.color: every colour channel must be between 0 and 1",
    );
    fails(
        "[materials.\"my red\"]\ncolor = [1, 0, 2]\n",
        2,
        9,
        "materials.\"my red\".color: every colour channel",
    );
}

#[test]
fn unknown_material() {
    fails(
        "[[objects]]\ntype = 'sphere'\nradius = 1\nmaterial = 'gold'\n",
        4,
        12,
        "objects[0].material: unknown material `gold` (none are defined)",
    );
    fails(
        "[materials.red]\ncolor = [1, 0, 0]\n[materials.blue]\ncolor = [0, 0, 1]\n\n[[objects]]\ntype = 'union'\nchildren = [\n  { type = 'sphere', radius = 1, material = 'green' },\n]\n",
        9,
        45,
        "objects[0].children[0].material: unknown material `green` (defined: blue, red)",
    );
}

#[test]
fn object_values() {
    let sphere = |extra: &str| format!("[[objects]]\ntype = 'sphere'\nradius = 1\n{extra}\n");
    fails("[[objects]]\ntype = 'sphere'\nradius = -1\n", 3, 10, "objects[0].radius: must be > 0, got -1");
    fails("[[objects]]\ntype = 'sphere'\nradius = 0\n", 3, 10, "objects[0].radius: must be > 0, got 0");
    fails(&sphere("scale = 0"), 4, 9, "objects[0].scale: every scale factor must be > 0, got 0");
    fails(
        &sphere("scale = [1, -1, 1]"),
        4,
        9,
        "objects[0].scale: every scale factor must be > 0, got [1, -1, 1]",
    );
    fails(
        "[[objects]]\ntype = 'box'\nhalf_size = [1, 0, 1]\n",
        3,
        13,
        "objects[0].half_size: every component must be > 0, got [1, 0, 1]",
    );
    fails(
        "[[objects]]\ntype = 'ellipsoid'\nradii = [1, 1, -2]\n",
        3,
        9,
        "objects[0].radii: every component must be > 0, got [1, 1, -2]",
    );
    fails(
        "[[objects]]\ntype = 'cylinder'\nradius = 1\nheight = 0\n",
        4,
        10,
        "objects[0].height: must be > 0, got 0",
    );
    fails(
        "[[objects]]\ntype = 'cylinder'\nradius = -1\nheight = 1\n",
        3,
        10,
        "objects[0].radius: must be > 0, got -1",
    );
    fails(
        "[[objects]]\ntype = 'cone'\nradius_bottom = 0\nheight = 1\n",
        3,
        17,
        "objects[0]: `radius_bottom` and `radius_top` must not both be 0",
    );
    fails(
        "[[objects]]\ntype = 'cone'\nradius_bottom = 1\nradius_top = -1\nheight = 1\n",
        4,
        14,
        "objects[0].radius_top: must be >= 0, got -1",
    );
    fails(
        "[[objects]]\ntype = 'cone'\nradius_bottom = 1\nheight = -2\n",
        4,
        10,
        "objects[0].height: must be > 0, got -2",
    );
    fails(
        "[[objects]]\ntype = 'torus'\nmajor_radius = 1\nminor_radius = 0\n",
        4,
        16,
        "objects[0].minor_radius: must be > 0, got 0",
    );
    fails(
        "[[objects]]\ntype = 'torus'\nmajor_radius = -1\nminor_radius = 1\n",
        3,
        16,
        "objects[0].major_radius: must be > 0, got -1",
    );
    fails(
        "[[objects]]\ntype = 'triangle'\na = [0, 0, 0]\nb = [1, 1, 1]\nc = [2, 2, 2]\n",
        5,
        5,
        "objects[0]: the triangle's vertices [0, 0, 0], [1, 1, 1] and [2, 2, 2] are collinear",
    );
    fails(
        "[[objects]]\ntype = 'triangle'\na = [0, 0, 0]\nb = [0, 0, 0]\nc = [1, 0, 0]\n",
        5,
        5,
        "are collinear",
    );
    fails(
        "[[objects]]\ntype = 'capsule'\na = [0, 0, 0]\nb = [0, 1, 0]\nradius = 0\n",
        5,
        10,
        "objects[0].radius: must be > 0, got 0",
    );
    fails(
        "[[objects]]\ntype = 'plane'\nnormal = [0, 0, 0]\n",
        3,
        10,
        "objects[0].normal: must not be a zero-length vector",
    );
    fails(
        "[[objects]]\ntype = 'plane'\noffset = 1\npoint = [0, 0, 0]\n",
        4,
        9,
        "objects[0]: give either `offset` or `point`, not both",
    );
}

#[test]
fn csg_and_repeat_values() {
    fails(
        "[[objects]]\ntype = 'subtraction'\nchildren = [{ type = 'sphere', radius = 1 }]\n",
        3,
        12,
        "objects[0].children: a subtraction needs at least 2 children, got 1",
    );
    fails(
        "[[objects]]\ntype = 'union'\nchildren = []\n",
        3,
        12,
        "objects[0].children: a union needs at least 1 child, got 0",
    );
    fails(
        "[[objects]]\ntype = 'intersection'\nchildren = []\n",
        3,
        12,
        "an intersection needs at least 1 child, got 0",
    );
    fails(
        "[[objects]]\ntype = 'smooth_union'\nblend = 0\nchildren = [{ type = 'sphere', radius = 1 }]\n",
        3,
        9,
        "objects[0].blend: must be > 0, got 0",
    );
    fails(
        "[[objects]]\ntype = 'union'\n[[objects.children]]\ntype = 'union'\n[[objects.children.children]]\ntype = 'sphere'\nradius = -3\n",
        7,
        10,
        "objects[0].children[0].children[0].radius: must be > 0, got -3",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [0, 0, 0]\n",
        3,
        10,
        "objects[0].period: every component must be >= 0 and at least one > 0, got [0, 0, 0]",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, -1, 0]\n",
        3,
        10,
        "objects[0].period: every component must be >= 0",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\ncount = [0, 1, 1]\n",
        4,
        9,
        "objects[0].count: every count must be an integer >= 1, got [0, 1, 1]",
    );
    fails(
        "[[objects]]\ntype = 'repeat'\nperiod = [1, 0, 0]\n[objects.child]\ntype = 'sphere'\nradius = -2\n",
        6,
        10,
        "objects[0].child.radius: must be > 0, got -2",
    );
}

#[test]
fn positions_count_characters_and_later_objects() {
    // Non-ASCII text before the value on the same line counts one column per character.
    fails("objects = [{ name = \"éé\", type = 'sphere', radius = -1 }]\n", 1, 53, "objects[0].radius");
    fails(
        "# ünïcode comment\n[materials.m]\ncolor = [1, 1, 1]\nior = -1 # négatif\n",
        4,
        7,
        "materials.m.ior",
    );
    // CRLF line endings.
    fails("[camera]\r\nfov = 0\r\n", 2, 7, "camera.fov");
    // The error is reported for the right element of an array of tables.
    let text = "[[objects]]\ntype = 'sphere'\nradius = 1\n\n[[objects]]\ntype = 'sphere'\nradius = 1\n\n[[objects]]\ntype = 'sphere'\nradius = -1\n";
    fails(text, 11, 10, "objects[2].radius: must be > 0, got -1");
}

#[test]
fn unreadable_file_is_an_io_error() {
    let path = Path::new("/nonexistent/dir/scene.toml");
    let err = load_scene(path).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(err.to_string().starts_with("/nonexistent/dir/scene.toml: "), "{err}");
}

#[test]
fn no_panic_on_mangled_input() {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/showcase.toml"))
            .unwrap();
    // Every prefix (cut at character boundaries), and every line removed in turn.
    for (i, _) in text.char_indices() {
        let _ = parse_scene(&text[..i], Path::new("cut.toml"));
    }
    let lines: Vec<&str> = text.lines().collect();
    for skip in 0..lines.len() {
        let mangled: Vec<&str> =
            lines.iter().enumerate().filter(|&(i, _)| i != skip).map(|(_, l)| *l).collect();
        let _ = parse_scene(&mangled.join("\n"), Path::new("cut.toml"));
    }
    // Deeply nested CSG up to (and past) the TOML parser's nesting limit.
    for depth in [10, 30, 60, 200] {
        let mut s = String::from("{ type = 'sphere', radius = 1 }");
        for _ in 0..depth {
            s = format!("{{ type = 'union', children = [{s}] }}");
        }
        let _ = parse_scene(&format!("objects = [{s}]\n"), Path::new("deep.toml"));
    }
}

// --- a complete valid scene -------------------------------------------------------------

const FULL: &str = r#"
[camera]
position = [1, 2, 3]
look_at = [1, 2, 13]
width = 320
height = 200

[settings]
background = [0.1, 0.2, 0.3]

[[lights]]
type = "ambient"
intensity = 0.25

[[lights]]
type = "point"
position = [0, 5, 0]
intensity = 1.5

[[lights]]
type = "directional"
direction = [0, -3, 4]
intensity = 0.5
color = [1, 0.5, 0.25]

[materials.zeta]      # defined first: index 0 although it sorts after "alpha"
color = [1, 0, 0]

[materials.alpha]
color = [0, 1, 0]
ka = 0.5
kd = 0.25
ks = 0.75
shininess = 32
reflectivity = 0.5
transparency = 0.25
ior = 1.5

[[objects]]            # no material anywhere: the default material, added at index 2
type = "sphere"
radius = 2
scale = 3

[[objects]]
name = "tree"
type = "union"
material = "alpha"
translate = [1, 2, 3]
rotate = [10, 20, 30]
scale = [1, 2, 0.5]

[[objects.children]]   # inherits alpha
type = "box"
half_size = [1, 2, 3]

[[objects.children]]   # its own material
type = "cylinder"
radius = 1
height = 4
material = "zeta"

[[objects.children]]   # nested: the grandchildren inherit alpha too
type = "smooth_subtraction"
blend = 0.5
children = [
    { type = "cone", radius_bottom = 1, height = 2 },
    { type = "torus", major_radius = 2, minor_radius = 3, material = "zeta" },
]

[[objects]]
type = "repeat"
period = [2, 0, 0]
count = [3, 1, 1]

[objects.child]
type = "plane"
normal = [0, 2, 0]
point = [5, 2, 7]
material = "zeta"

[[objects]]
type = "intersection"  # no material: takes its first child's
children = [
    { type = "ellipsoid", radii = [1, 2, 3], material = "alpha" },
    { type = "capsule", a = [0, 0, 0], b = [0, 1, 0], radius = 0.5, material = "zeta" },
    { type = "triangle", a = [0, 0, 0], b = [1, 0, 0], c = [0, 1, 0], material = "zeta" },
]

[[objects]]
type = "smooth_intersection"
blend = 0.25
material = "zeta"
children = [{ type = "plane" }, { type = "cone", radius_bottom = 0, radius_top = 2, height = 1 }]
"#;

#[test]
fn full_scene_round_trips() {
    let s = ok(FULL);

    assert_eq!(
        s.camera,
        Camera {
            position: Vec3::new(1.0, 2.0, 3.0),
            forward: Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: Camera::default().fov_y_deg,
            width: 320,
            height: 200,
        }
    );
    assert!((s.camera.fov_y_deg - 53.130_104).abs() < 1e-4);
    assert_eq!(
        s.settings,
        Settings {
            max_depth: 3,
            background: Vec3::new(0.1, 0.2, 0.3),
            max_distance: 1.0e5,
            ..Settings::default()
        }
    );

    assert_eq!(s.lights.len(), 3);
    assert_eq!(s.lights[0], Light::Ambient { intensity: 0.25 });
    assert_eq!(
        s.lights[1],
        Light::Point { position: Vec3::new(0.0, 5.0, 0.0), intensity: 1.5, color: Vec3::ONE }
    );
    match s.lights[2] {
        Light::Directional { direction, intensity, color } => {
            assert!(close(direction, Vec3::new(0.0, -0.6, 0.8)), "{direction}");
            assert_eq!(intensity, 0.5);
            assert_eq!(color, Vec3::new(1.0, 0.5, 0.25));
        }
        other => panic!("{other:?}"),
    }

    let names: Vec<&str> = s.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["zeta", "alpha", "default"]);
    assert_eq!(s.materials[0], Material { name: "zeta".into(), color: Vec3::X, ..Material::default() });
    assert_eq!(
        s.materials[1],
        Material {
            name: "alpha".into(),
            color: Vec3::Y,
            ka: 0.5,
            kd: 0.25,
            ks: 0.75,
            shininess: Some(32.0),
            reflectivity: 0.5,
            transparency: 0.25,
            ior: 1.5,
        }
    );
    assert_eq!(s.materials[2], Material::default());
    let (zeta, alpha, default) = (0, 1, 2);

    assert_eq!(s.objects.len(), 5);

    // objects[0]: uniform scale from a number, the default material, positional label.
    let o = &s.objects[0];
    assert_eq!(o.kind, ObjectKind::Primitive(Primitive::Sphere { radius: 2.0 }));
    assert_eq!(o.transform, TransformDesc { scale: Vec3::splat(3.0), ..Default::default() });
    assert_eq!(o.material, default);
    assert_eq!(o.label, "objects[0]");

    // objects[1]: a named union with a full transform; children inherit its material.
    let o = &s.objects[1];
    assert_eq!(o.label, "tree");
    assert_eq!(o.material, alpha);
    assert_eq!(
        o.transform,
        TransformDesc {
            translate: Vec3::new(1.0, 2.0, 3.0),
            rotate_deg: Vec3::new(10.0, 20.0, 30.0),
            scale: Vec3::new(1.0, 2.0, 0.5),
        }
    );
    let ObjectKind::Csg { op, children } = &o.kind else { panic!("{:?}", o.kind) };
    assert_eq!(*op, CsgOp::Union);
    assert_eq!(children.len(), 3);
    assert_eq!(children[0].kind, ObjectKind::Primitive(Primitive::Box { half: Vec3::new(1.0, 2.0, 3.0) }));
    assert_eq!(children[0].material, alpha);
    assert_eq!(children[0].label, "objects[1].children[0]");
    assert_eq!(children[0].transform, TransformDesc::default());
    assert_eq!(
        children[1].kind,
        ObjectKind::Primitive(Primitive::Cylinder { radius: 1.0, half_height: 2.0 })
    );
    assert_eq!(children[1].material, zeta);
    let ObjectKind::Csg { op, children: grandchildren } = &children[2].kind else {
        panic!("{:?}", children[2].kind)
    };
    assert_eq!(*op, CsgOp::SmoothSubtraction { k: 0.5 });
    assert_eq!(children[2].material, alpha);
    assert_eq!(
        grandchildren[0].kind,
        ObjectKind::Primitive(Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 })
    );
    assert_eq!(grandchildren[0].material, alpha);
    assert_eq!(grandchildren[0].label, "objects[1].children[2].children[0]");
    assert_eq!(grandchildren[1].kind, ObjectKind::Primitive(Primitive::Torus { major: 2.0, minor: 3.0 }));
    assert_eq!(grandchildren[1].material, zeta);

    // objects[2]: finite repetition of a plane given by a point; normal normalised.
    let o = &s.objects[2];
    let ObjectKind::Repeat { period, count, child } = &o.kind else { panic!("{:?}", o.kind) };
    assert_eq!(*period, Vec3::new(2.0, 0.0, 0.0));
    assert_eq!(*count, Some(UVec3::new(3, 1, 1)));
    assert_eq!(child.kind, ObjectKind::Primitive(Primitive::Plane { normal: Vec3::Y, offset: 2.0 }));
    assert_eq!(child.material, zeta);
    assert_eq!(child.label, "objects[2].child");
    assert_eq!(o.material, zeta, "a repeat without material takes its child's");

    // objects[3]: no material of its own: the first child's.
    let o = &s.objects[3];
    let ObjectKind::Csg { op, children } = &o.kind else { panic!("{:?}", o.kind) };
    assert_eq!(*op, CsgOp::Intersection);
    assert_eq!(o.material, alpha);
    assert_eq!(
        children[0].kind,
        ObjectKind::Primitive(Primitive::Ellipsoid { radii: Vec3::new(1.0, 2.0, 3.0) })
    );
    assert_eq!(
        children[1].kind,
        ObjectKind::Primitive(Primitive::Capsule { a: Vec3::ZERO, b: Vec3::Y, radius: 0.5 })
    );
    assert_eq!(
        children[2].kind,
        ObjectKind::Primitive(Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: Vec3::Y })
    );
    assert_eq!(children[2].material, zeta);

    // objects[4]: the plane's defaults; a cone with its apex at the bottom.
    let ObjectKind::Csg { op, children } = &s.objects[4].kind else { panic!() };
    assert_eq!(*op, CsgOp::SmoothIntersection { k: 0.25 });
    assert_eq!(children[0].kind, ObjectKind::Primitive(Primitive::Plane { normal: Vec3::Y, offset: 0.0 }));
    assert_eq!(children[0].material, zeta);
    assert_eq!(
        children[1].kind,
        ObjectKind::Primitive(Primitive::Cone { radius_bottom: 0.0, radius_top: 2.0, half_height: 0.5 })
    );
}

#[test]
fn empty_file_gives_the_defaults() {
    let s = ok("");
    assert_eq!(s.camera, Camera::default());
    assert_eq!(s.settings, Settings::default());
    assert!(s.lights.is_empty());
    assert!(s.objects.is_empty());
    // `Scene::materials` is never empty.
    assert_eq!(s.materials, vec![Material::default()]);
}

#[test]
fn default_material_only_when_used() {
    let s = ok(
        "[materials.red]\ncolor = [1, 0, 0]\n[[objects]]\ntype = 'sphere'\nradius = 1\nmaterial = 'red'\n",
    );
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.objects[0].material, 0);

    // A material the file names "default" is used for objects without one.
    let s = ok(
        "[materials.red]\ncolor = [1, 0, 0]\n[materials.default]\ncolor = [0, 0, 1]\n[[objects]]\ntype = 'sphere'\nradius = 1\n",
    );
    assert_eq!(s.materials.len(), 2);
    assert_eq!(s.objects[0].material, 1);
    assert_eq!(s.materials[1].color, Vec3::Z);
}

#[test]
fn camera_direction_and_up() {
    let s = ok("[camera]\ndirection = [3, 0, 4]\nup = [0, 0.5, 0]\nfov = 90\n");
    assert!(close(s.camera.forward, Vec3::new(0.6, 0.0, 0.8)));
    assert_eq!(s.camera.up, Vec3::Y);
    assert_eq!(s.camera.fov_y_deg, 90.0);
    assert_eq!((s.camera.width, s.camera.height), (500, 500));
    let s = ok("[camera]\nposition = [0, 5, 0]\nlook_at = [0, 0, 0]\nup = [0, 0, 1]\n");
    assert!(close(s.camera.forward, -Vec3::Y));
    assert_eq!(s.camera.up, Vec3::Z);
}

#[test]
fn thesis_scene_values() {
    let s = load_scene(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thesis_rt.toml")).unwrap();
    assert_eq!(s.camera, Camera::default());
    assert_eq!(s.settings.max_depth, 3);
    assert_eq!(s.objects.len(), 4);
    let Light::Directional { direction, .. } = s.lights[2] else { panic!() };
    assert!(close(direction, -Vec3::new(1.0, 4.0, 4.0).normalize()));
}

#[test]
fn mesh_objects_load_relative_to_the_scene_and_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("tri.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let scene_path = dir.path().join("s.toml");
    let text = "[[objects]]\ntype = \"mesh\"\npath = \"tri.obj\"\nshading = \"smooth\"\n";
    std::fs::write(&scene_path, text).unwrap();
    let scene = load_scene(&scene_path).unwrap();
    match &scene.objects[0].kind {
        ObjectKind::Mesh { mesh, shading, .. } => {
            assert_eq!(mesh.triangles.len(), 4);
            assert_eq!(*shading, sdfmesh::scene::shape::Shading::Smooth);
        }
        other => panic!("{other:?}"),
    }
    assert!(scene.objects[0].bounds().is_some());
    // A missing mesh file names the mesh file.
    std::fs::write(&scene_path, text.replace("tri.obj", "nope.obj")).unwrap();
    let err = load_scene(&scene_path).unwrap_err();
    assert!(err.to_string().contains("nope.obj"), "{err}");
    assert_eq!(err.exit_code(), 2);
    // Meshes cannot be CSG children; bad shading names the key.
    let nested = "[[objects]]\ntype = \"union\"\n[[objects.children]]\ntype = \"mesh\"\npath = \"tri.obj\"\n";
    std::fs::write(&scene_path, nested).unwrap();
    let err = load_scene(&scene_path).unwrap_err().to_string();
    assert!(err.contains("top-level"), "{err}");
    std::fs::write(&scene_path, text.replace("smooth", "glossy")).unwrap();
    let err = load_scene(&scene_path).unwrap_err().to_string();
    assert!(err.contains("s.toml:4:") && err.contains("shading"), "{err}");
}

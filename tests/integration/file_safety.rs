//! Which files the toolkit opens, reads and writes (issue #32, classes 5, 7 and 8), one
//! test per class of failure:
//!
//! - special files as inputs (a FIFO blocked forever, `/dev/zero` read without end):
//!   refused fast, by name, directly, through a link and as a scene's mesh or grid `path`;
//! - a glTF file's external buffers reaching out of its folder (`..`, absolute paths,
//!   `file://`, links): refused, without quoting the other file's bytes;
//! - outputs that are inputs of the same command (after links), outputs that are not
//!   regular files (`/dev/null`, a folder, a FIFO) and outputs that are links.
//!
//! Every run that could block goes through a watchdog, so a regression fails instead of
//! hanging the suite.

use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{FileTypeExt, symlink};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use sdfmesh::error::Error;

use crate::util::{put, temp_dir};

/// Longest a refusal may take: it must not read or wait on anything.
const FAST: Duration = Duration::from_secs(5);
/// When the watchdog gives up on a run and fails the test.
const WATCHDOG: Duration = Duration::from_secs(30);

const SCENE: &str = r#"
[camera]
position = [0, 0, -4]
look_at = [0, 0, 0]
width = 32
height = 24

[[lights]]
type = "ambient"
intensity = 0.5

[[objects]]
type = "sphere"
radius = 1
"#;

/// Makes a FIFO at `path`.
fn mkfifo(path: &Path) -> PathBuf {
    let c = CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: `c` is a valid NUL-terminated path that outlives the call.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo {}: {}", path.display(), std::io::Error::last_os_error());
    path.to_path_buf()
}

/// Runs the toolkit on `args` under the watchdog; returns its output and how long it took.
fn toolkit_timed(args: &[&str]) -> (Output, Duration) {
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_toolkit"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run toolkit");
    loop {
        if child.try_wait().expect("wait").is_some() {
            break;
        }
        if start.elapsed() > WATCHDOG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("toolkit {args:?} still running after {WATCHDOG:?}: it blocks");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let took = start.elapsed();
    (child.wait_with_output().expect("output"), took)
}

/// Runs the toolkit on `args`, which must fail at once with exit code 2 and one line
/// holding every needle; returns that line.
#[track_caller]
fn refused(args: &[&str], needles: &[&str]) -> String {
    let (o, took) = toolkit_timed(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {err:?} lacks {n:?}");
    }
    assert!(took < FAST, "{args:?} took {took:?}");
    err
}

/// Runs `f` on another thread under the watchdog and returns its result.
fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(WATCHDOG).expect("the call blocks")
}

/// The library call `f` on `path` fails fast with an error naming `path` and `needle`.
#[track_caller]
fn lib_refused<T: Send + 'static>(path: &Path, needle: &str, f: fn(&Path) -> Result<T, Error>) {
    lib_refused_naming(path, path, needle, f);
}

/// As [`lib_refused`], the error naming `named` (a file that `path` names).
#[track_caller]
fn lib_refused_naming<T: Send + 'static>(
    path: &Path,
    named: &Path,
    needle: &str,
    f: fn(&Path) -> Result<T, Error>,
) {
    let p = path.to_path_buf();
    let start = Instant::now();
    let r = within(move || f(&p).map(|_| ()));
    let e = r.expect_err("expected an error");
    let msg = e.to_string();
    assert!(msg.starts_with(&named.display().to_string()), "does not name the file: {msg}");
    assert!(msg.contains(needle), "{msg:?} lacks {needle:?}");
    assert_eq!(e.exit_code(), 2);
    assert!(start.elapsed() < FAST, "{msg}");
}

fn load_mesh(p: &Path) -> Result<sdfmesh::mesh::TriangleMesh, Error> {
    sdfmesh::mesh::load_mesh(p).map(|(m, _)| m)
}

fn load_grid(p: &Path) -> Result<sdfmesh::geometry::grid::SdfGrid, Error> {
    sdfmesh::geometry::grid::io::load_grid(p)
}

fn load_scene(p: &Path) -> Result<sdfmesh::scene::Scene, Error> {
    sdfmesh::scene::load_scene(p)
}

fn load_cases(p: &Path) -> Result<Vec<sdfmesh::compare::hard::Case>, Error> {
    sdfmesh::compare::hard::load_cases(p)
}

/// Names of the files in `dir` starting with `.` (where temporary files go).
fn hidden(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with('.'))
        .collect()
}

// ---------------------------------------------------------------- class 5: special inputs

/// A FIFO as any input (scene, mesh, grid, manifest; to every command that reads one) is
/// refused at once, named as a FIFO: the open used to wait for a writer forever.
#[test]
fn fifo_inputs_are_refused_without_blocking() {
    let dir = temp_dir("fifo-in");
    let out = dir.join("out.png");
    let out_s = out.to_str().unwrap();
    for name in ["s.toml", "m.obj", "m.glb", "m.stl", "m.ply", "g.sdf", "g.npy", "noext"] {
        let f = mkfifo(&dir.join(name));
        let f_s = f.to_str().unwrap();
        refused(&["render", f_s, "-o", out_s], &[name, "is a FIFO, not a regular file"]);
    }
    let f = dir.join("m.obj");
    refused(
        &["convert", f.to_str().unwrap(), "--to", "grid", "-o", dir.join("g.out.sdf").to_str().unwrap()],
        &["m.obj", "is a FIFO"],
    );
    let s = dir.join("s.toml");
    let o = dir.join("x.obj");
    refused(
        &["convert", s.to_str().unwrap(), "--to", "mesh", "-o", o.to_str().unwrap()],
        &["s.toml", "is a FIFO"],
    );
    let manifest = mkfifo(&dir.join("cases.toml"));
    refused(&["hard", manifest.to_str().unwrap()], &["cases.toml", "is a FIFO"]);
    // The library's loaders, each under the watchdog.
    lib_refused(&dir.join("m.obj"), "is a FIFO", load_mesh);
    lib_refused(&dir.join("g.sdf"), "is a FIFO", load_grid);
    lib_refused(&dir.join("s.toml"), "is a FIFO", load_scene);
    lib_refused(&manifest, "is a FIFO", load_cases);
    // A scene whose mesh or grid `path` is a FIFO.
    let s = put(&dir, "mesh_fifo.toml", format!("{SCENE}\n[[objects]]\ntype = \"mesh\"\npath = \"m.obj\"\n"));
    lib_refused_naming(&s, &dir.join("m.obj"), "is a FIFO", load_scene);
    let s = put(&dir, "grid_fifo.toml", format!("{SCENE}\n[[objects]]\ntype = \"grid\"\npath = \"g.sdf\"\n"));
    lib_refused_naming(&s, &dir.join("g.sdf"), "is a FIFO", load_scene);
    assert!(!out.exists());
    assert_eq!(hidden(&dir), Vec::<String>::new());
}

/// `/dev/zero` as an input, directly, through a symbolic link with a mesh's or grid's
/// extension, and as a scene's mesh `path`: refused before a byte is read (it used to be
/// read until memory ran out); regular files over the size limits likewise.
#[test]
fn dev_zero_is_refused_directly_through_a_link_and_from_a_scene() {
    let dir = temp_dir("zero");
    let out = dir.join("out.png");
    let out_s = out.to_str().unwrap();
    refused(
        &["render", "/dev/zero", "-o", out_s],
        &["/dev/zero", "is a character device, not a regular file"],
    );
    for name in ["zero.obj", "zero.stl", "zero.ply", "zero.glb", "zero.sdf", "zero.npy", "zero.toml"] {
        let link = dir.join(name);
        symlink("/dev/zero", &link).unwrap();
        refused(&["render", link.to_str().unwrap(), "-o", out_s], &[name, "is a character device"]);
    }
    lib_refused(&dir.join("zero.stl"), "is a character device", load_mesh);
    lib_refused(&dir.join("zero.sdf"), "is a character device", load_grid);
    // A scene naming it as a mesh, through the link and as an absolute path to the device.
    for (name, path) in [("via_link.toml", "zero.stl"), ("via_dev.toml", "/dev/zero")] {
        let s = put(&dir, name, format!("{SCENE}\n[[objects]]\ntype = \"mesh\"\npath = \"{path}\"\n"));
        let err = refused(&["render", s.to_str().unwrap(), "-o", out_s], &[]);
        assert!(err.contains("zero"), "{err}");
    }
    let s =
        put(&dir, "grid_zero.toml", format!("{SCENE}\n[[objects]]\ntype = \"grid\"\npath = \"zero.sdf\"\n"));
    refused(&["render", s.to_str().unwrap(), "-o", out_s], &["zero.sdf", "is a character device"]);
    // Regular files over the size limits (sparse: no disk used) are refused before they
    // are read, and so never take their size in memory.
    let big = dir.join("big.stl");
    std::fs::File::create(&big).unwrap().set_len(sdfmesh::files::MAX_INPUT_BYTES + 1).unwrap();
    let limit = format!("more than the limit of {} bytes", sdfmesh::files::MAX_INPUT_BYTES);
    refused(&["render", big.to_str().unwrap(), "-o", out_s], &["big.stl", &limit]);
    let big = dir.join("big.toml");
    std::fs::File::create(&big).unwrap().set_len(sdfmesh::files::MAX_TEXT_BYTES + 1).unwrap();
    let limit = format!("more than the limit of {} bytes", sdfmesh::files::MAX_TEXT_BYTES);
    refused(&["render", big.to_str().unwrap(), "-o", out_s], &["big.toml", &limit]);
    // A folder as an input.
    let sub = dir.join("folder.obj");
    std::fs::create_dir(&sub).unwrap();
    refused(&["render", sub.to_str().unwrap(), "-o", out_s], &["folder.obj", "is a directory"]);
    assert!(!out.exists());
}

// ---------------------------------------------------------------- class 8: glTF containment

/// A glTF document with positions in buffer 0 (a data URI: one triangle) and `u16`
/// indices in buffer 1 at `uri`, 6 bytes long.
fn gltf_with_index_buffer(uri: &str) -> String {
    let mut pos = Vec::new();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        pos.extend_from_slice(&v.to_le_bytes());
    }
    let b64 = base64(&pos);
    format!(
        r#"{{"asset":{{"version":"2.0"}},
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}},
                     {{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}},{{"buffer":1,"byteLength":6}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}},
                   {{"byteLength":6,"uri":"{uri}"}}]}}"#
    )
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// External buffers must lie in the glTF file's folder: `..`, absolute paths, `file://`
/// and links out of it are refused with one line naming the glTF file and the buffer, and
/// the other file's bytes never appear (its "mo" used to come back as "index 28525").
/// Buffers in the folder, also through `sub/..`, still load; a FIFO there fails fast.
#[test]
fn gltf_buffers_stay_inside_the_model_folder() {
    let dir = temp_dir("gltf");
    let model = dir.join("model");
    std::fs::create_dir_all(model.join("sub")).unwrap();
    // Outside the model's folder: bytes that, read as u16 indices, say 28525 ("mo").
    let secret = put(&dir, "secret.bin", b"momomo");
    let inside = [0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>();
    put(&model, "idx.bin", &inside);
    put(&model.join("sub"), "idx.bin", &inside);
    symlink(&secret, model.join("link.bin")).unwrap();
    let absolute = secret.to_str().unwrap().to_string();
    let outside = [
        ("dotdot.gltf", "../secret.bin".to_string()),
        ("deep.gltf", "sub/../../secret.bin".to_string()),
        ("absolute.gltf", absolute.clone()),
        ("link.gltf", "link.bin".to_string()),
        ("escaped.gltf", "..%2Fsecret.bin".to_string()),
        ("fileuri.gltf", format!("file://{absolute}")),
    ];
    for (name, uri) in &outside {
        let p = put(&model, name, gltf_with_index_buffer(uri));
        let e = within({
            let p = p.clone();
            move || load_mesh(&p)
        })
        .expect_err(name);
        let msg = e.to_string();
        assert!(msg.starts_with(&p.display().to_string()), "{msg}");
        assert!(msg.contains("buffer 1"), "{msg}");
        assert!(msg.contains("outside the folder") || msg.contains("not supported"), "{msg}");
        assert!(!msg.contains("28525") && !msg.contains("momomo"), "{msg}");
        assert!(!msg.contains('\n'));
        assert_eq!(e.exit_code(), 2);
        // The same through the binary.
        let out = dir.join("out.png");
        let err = refused(&["render", p.to_str().unwrap(), "-o", out.to_str().unwrap()], &["buffer 1"]);
        assert!(!err.contains("28525"), "{err}");
    }
    for (name, uri) in
        [("plain.gltf", "idx.bin"), ("via_sub.gltf", "sub/../idx.bin"), ("in_sub.gltf", "sub/idx.bin")]
    {
        let p = put(&model, name, gltf_with_index_buffer(uri));
        let m = load_mesh(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m.triangles.len(), 1, "{name}");
    }
    // A byteLength over the size limit, on a sparse file that really is that long.
    let big = model.join("big.bin");
    std::fs::File::create(&big).unwrap().set_len(sdfmesh::files::MAX_INPUT_BYTES + 2).unwrap();
    let doc = gltf_with_index_buffer("big.bin").replace(
        r#""byteLength":6,"uri""#,
        &format!(r#""byteLength":{},"uri""#, sdfmesh::files::MAX_INPUT_BYTES + 2),
    );
    let p = put(&model, "big.gltf", doc);
    lib_refused(&p, "buffer 1: cannot read 'big.bin'", load_mesh);
    lib_refused(&p, "more than the limit", load_mesh);
    mkfifo(&model.join("fifo.bin"));
    let p = put(&model, "fifo.gltf", gltf_with_index_buffer("fifo.bin"));
    lib_refused(&p, "buffer 1: cannot read 'fifo.bin'", load_mesh);
    lib_refused(&p, "is a FIFO", load_mesh);
}

// ---------------------------------------------------------------- class 7: outputs

/// An output that is an input of the same command, named directly, through `..` or
/// through a link, is refused with exit code 2 before any work and the input is left
/// byte for byte: `render`, `compare`, `convert` (both ways) and `hard`.
#[test]
fn an_output_that_is_an_input_is_refused() {
    let dir = temp_dir("same");
    let scene = put(&dir, "x.toml", SCENE);
    let original = std::fs::read(&scene).unwrap();
    std::fs::create_dir(dir.join("sub")).unwrap();
    let dotted = dir.join("sub/../x.toml");
    let alias = dir.join("alias.png");
    symlink(&scene, &alias).unwrap();
    let s = scene.to_str().unwrap();
    for out in [&scene, &dotted, &alias] {
        let o = out.to_str().unwrap();
        refused(&["render", s, "-o", o], &["is the input", "x.toml"]);
        refused(&["compare", s, "--csv", o, "--overwrite", "--res", "8", "--frames", "1"], &["is the input"]);
        refused(&["compare", s, "--csv", o, "--resume", "--res", "8", "--frames", "1"], &["is the input"]);
        assert_eq!(std::fs::read(&scene).unwrap(), original, "{}", out.display());
    }
    // --summary-json too, and two outputs that are one file.
    let csv = dir.join("y.csv");
    let c = csv.to_str().unwrap();
    refused(
        &["compare", s, "--csv", c, "--summary-json", s, "--res", "8", "--frames", "1"],
        &["is the input"],
    );
    refused(
        &["compare", s, "--csv", c, "--summary-json", c, "--res", "8", "--frames", "1"],
        &["also the output"],
    );
    assert!(!csv.exists());
    // convert --to mesh reads a scene whatever its extension: `x.obj` is a scene here.
    let scene_obj = put(&dir, "scene.obj", SCENE);
    let so = scene_obj.to_str().unwrap();
    refused(&["convert", so, "--to", "mesh", "--res", "8", "-o", so], &["is the input"]);
    assert_eq!(std::fs::read(&scene_obj).unwrap(), SCENE.as_bytes());
    // convert --to grid: the output is a link to the mesh.
    let mesh = put(&dir, "m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
    let mesh_bytes = std::fs::read(&mesh).unwrap();
    let grid_alias = dir.join("m.sdf");
    symlink(&mesh, &grid_alias).unwrap();
    refused(
        &[
            "convert",
            mesh.to_str().unwrap(),
            "--to",
            "grid",
            "--res",
            "8",
            "-o",
            grid_alias.to_str().unwrap(),
        ],
        &["is the input"],
    );
    assert_eq!(std::fs::read(&mesh).unwrap(), mesh_bytes);
    // hard: the table over its manifest.
    let manifest = put(&dir, "cases.toml", "");
    let m = manifest.to_str().unwrap();
    refused(&["hard", m, "--table", m], &["is the input"]);
    assert_eq!(std::fs::read(&manifest).unwrap(), b"");
    assert_eq!(hidden(&dir), Vec::<String>::new());
}

/// A file the input names (a scene's mesh, a glTF file's buffer) is an input too: the
/// command line does not show it, so it is refused when the write comes, and left as it was.
#[test]
fn an_output_that_an_input_names_is_refused() {
    let dir = temp_dir("named");
    let mesh = put(&dir, "m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
    let bytes = std::fs::read(&mesh).unwrap();
    let scene = put(&dir, "s.toml", format!("{SCENE}\n[[objects]]\ntype = \"mesh\"\npath = \"m.obj\"\n"));
    let (s, m) = (scene.to_str().unwrap(), mesh.to_str().unwrap());
    refused(&["render", s, "-o", m], &["m.obj", "read as an input"]);
    refused(&["compare", s, "--csv", m, "--overwrite", "--res", "8", "--frames", "1"], &["read as an input"]);
    assert_eq!(std::fs::read(&mesh).unwrap(), bytes);
    assert_eq!(hidden(&dir), Vec::<String>::new());
    // The library alone does not refuse: a program may save over a file it loaded.
    let loaded = sdfmesh::mesh::load_mesh(&mesh).unwrap();
    drop(loaded);
    sdfmesh::files::write_atomic_bytes(&dir.join("m.obj"), &bytes).unwrap();
}

/// An output that is not a regular file (`/dev/null`, a folder, a FIFO) is refused by
/// name before a temporary file is made, and nothing is left behind; renaming over it
/// used to replace a device node (as root) with the PNG.
#[test]
fn an_output_that_is_not_a_regular_file_is_refused() {
    let dir = temp_dir("special-out");
    let scene = put(&dir, "s.toml", SCENE);
    let s = scene.to_str().unwrap();
    refused(&["render", s, "-o", "/dev/null"], &["/dev/null", "is a character device, not a regular file"]);
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    assert!(!hidden(Path::new("/dev")).iter().any(|n| n.starts_with(".null.tmp")));
    let folder = dir.join("out.png");
    std::fs::create_dir(&folder).unwrap();
    refused(&["render", s, "-o", folder.to_str().unwrap()], &["out.png", "is a directory"]);
    assert!(folder.is_dir());
    let fifo = mkfifo(&dir.join("fifo.png"));
    refused(&["render", s, "-o", fifo.to_str().unwrap()], &["fifo.png", "is a FIFO"]);
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    // compare's CSV (appended to, not renamed over) and summary, hard's table: refused
    // before any work, where opening the FIFO used to wait for a reader forever.
    let f = fifo.to_str().unwrap();
    refused(
        &["compare", s, "--csv", f, "--res", "8", "--frames", "1", "--quiet"],
        &["fifo.png", "is a FIFO"],
    );
    refused(&["compare", s, "--csv", f, "--resume", "--res", "8", "--frames", "1"], &["is a FIFO"]);
    refused(
        &["compare", s, "--csv", "/dev/null", "--overwrite", "--res", "8", "--frames", "1"],
        &["is a character"],
    );
    let csv = dir.join("c.csv");
    let c = csv.to_str().unwrap();
    refused(&["compare", s, "--csv", c, "--summary-json", f, "--res", "8", "--frames", "1"], &["is a FIFO"]);
    assert!(!csv.exists());
    let manifest = put(&dir, "cases.toml", "");
    refused(&["hard", manifest.to_str().unwrap(), "--table", f], &["is a FIFO"]);
    // A link to a device is followed to the device and refused the same way.
    let link = dir.join("null.png");
    symlink("/dev/null", &link).unwrap();
    refused(&["render", s, "-o", link.to_str().unwrap()], &["null.png", "is a character device"]);
    // The library's writers refuse it too.
    let mesh = sdfmesh::convert::tessellate::tessellate(
        &sdfmesh::scene::shape::Primitive::Sphere { radius: 1.0 },
        8,
        None,
    );
    let e = sdfmesh::mesh::save_mesh(&mesh, &dir.join("fifo.png").with_extension("obj")).map(|_| ());
    assert!(e.is_ok(), "a new regular file is fine");
    let bad = dir.join("d.obj");
    std::fs::create_dir(&bad).unwrap();
    let e = sdfmesh::mesh::save_mesh(&mesh, &bad).unwrap_err().to_string();
    assert!(e.contains("d.obj") && e.contains("is a directory"), "{e}");
    assert_eq!(hidden(&dir), Vec::<String>::new());
}

/// An output that is a symbolic link is written through: the file it points to gets the
/// PNG and the link stays a link (also a dangling one, which creates its target).
#[test]
fn an_output_link_is_written_through() {
    let dir = temp_dir("link-out");
    let scene = put(&dir, "s.toml", SCENE);
    std::fs::create_dir(dir.join("real")).unwrap();
    let target = put(&dir.join("real"), "image.png", b"old");
    let link = dir.join("link.png");
    symlink("real/image.png", &link).unwrap();
    let dangling = dir.join("dangling.png");
    symlink("real/new.png", &dangling).unwrap();
    for out in [&link, &dangling] {
        let (o, _) = toolkit_timed(&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(std::fs::symlink_metadata(out).unwrap().file_type().is_symlink(), "{}", out.display());
    }
    for real in [&target, &dir.join("real/new.png")] {
        let img = image::open(real).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (32, 24));
    }
    assert_eq!(hidden(&dir), Vec::<String>::new());
    assert_eq!(hidden(&dir.join("real")), Vec::<String>::new());
}

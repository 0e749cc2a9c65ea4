//! Fuzz target: the scene parser `sdfmesh::scene::parse_scene` on UTF-8 text. The scene's
//! path lies in an empty scratch folder, so relative mesh paths find nothing (absolute
//! ones are read like any scene would). Any input must give a scene whose objects use
//! existing materials, or a one-line error naming the scene (or the mesh file it failed
//! to load).

#![no_main]

use libfuzzer_sys::fuzz_target;
use sdfmesh::error::Error;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = sdfmesh_fuzz::scratch_dir().join("scene.toml");
    match sdfmesh::scene::parse_scene(text, &path) {
        Ok(scene) => {
            assert!(!scene.materials.is_empty(), "a scene always has a material");
            for o in &scene.objects {
                assert!(
                    (o.material as usize) < scene.materials.len(),
                    "{}: material {} of {}",
                    o.label,
                    o.material,
                    scene.materials.len()
                );
            }
        }
        Err(e) => {
            // Errors name the scene, or the file a `mesh` object failed to load (whatever
            // its name: `path = "x"` fails with "x: no file extension ...").
            let named = match &e {
                Error::Input { path: p, .. } | Error::Io { path: p, .. } => p.clone(),
                Error::Usage(m) => panic!("usage error from a scene file: {m}"),
                Error::Batch { message, .. } => panic!("batch error from a scene file: {message}"),
            };
            sdfmesh_fuzz::check_error(&named, &e);
        }
    }
});

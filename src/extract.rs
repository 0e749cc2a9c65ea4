//! Extraction of triangle meshes from signed distance functions (in progress).

//! The TOML scene file format: parsing with serde, validation with file:line:column
//! errors, and conversion into a [`Scene`].

use std::path::Path;

use super::Scene;
use crate::error::{Error, Result};

/// Reads and parses the scene file at `path`.
pub fn load_scene(path: &Path) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_scene(&text, path)
}

/// Parses scene text; `path` is used in messages and to resolve relative paths.
pub fn parse_scene(_text: &str, path: &Path) -> Result<Scene> {
    Err(Error::input(
        path,
        None,
        "scene parsing not implemented yet",
    ))
}

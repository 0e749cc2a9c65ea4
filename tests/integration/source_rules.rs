//! Rules the source tree keeps (issue #33), checked by reading every file under `src/`:
//! `unsafe`, intrinsics and `#[target_feature]` only in the SIMD layer (`src/simd/`); every
//! `unsafe` there with a `SAFETY` note (just above it, or a note covering the blocks below);
//! no file over 1400 lines; a `//!` header on every file.

/// The code of a line: what comes before a `//` comment (a `//` inside a string literal
/// cuts the line short, which can only hide code, never invent it).
fn code(line: &str) -> &str {
    line.find("//").map_or(line, |i| &line[..i])
}

/// Whether `word` occurs in `text` as a whole word.
fn has_word(text: &str, word: &str) -> bool {
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        let ident = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        !ident(before) && !ident(after)
    })
}

fn in_simd(path: &str) -> bool {
    path.starts_with("simd/")
}

#[test]
fn unsafe_and_intrinsics_only_in_the_simd_layer() {
    let mut bad = Vec::new();
    for (path, text) in crate::util::crate_sources() {
        if in_simd(&path) {
            continue;
        }
        for (n, line) in text.lines().enumerate() {
            let c = code(line);
            if has_word(c, "unsafe")
                || c.contains("std::arch")
                || c.contains("core::arch")
                || c.contains("target_feature")
                || c.contains("_mm_")
                || c.contains("_mm256_")
            {
                bad.push(format!("src/{path}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(bad.is_empty(), "unsafe or intrinsics outside src/simd/:\n{}", bad.join("\n"));
}

#[test]
fn every_unsafe_in_the_simd_layer_has_a_safety_note() {
    let mut bad = Vec::new();
    let mut blocks = 0;
    for (path, text) in crate::util::crate_sources() {
        if !in_simd(&path) {
            continue;
        }
        let lines: Vec<&str> = text.lines().collect();
        // A note at the start of a line that says which blocks it covers, such as
        // `// SAFETY (every block below): ...`, covers the rest of the file.
        let mut region = false;
        for (n, line) in lines.iter().enumerate() {
            if line.starts_with("// SAFETY (") || line.starts_with("    // SAFETY (") {
                region = true;
            }
            let c = code(line);
            if !has_word(c, "unsafe") {
                continue;
            }
            blocks += 1;
            // The note: a region note above, a comment with `SAFETY` on this line or in the
            // comment lines (and attributes) just above, or, for an `unsafe fn`, a
            // `# Safety` doc section.
            let mut ok = region || line.contains("SAFETY");
            let mut k = n;
            while !ok && k > 0 {
                k -= 1;
                let t = lines[k].trim();
                if t.starts_with("//") || t.starts_with("#[") {
                    ok = t.contains("SAFETY") || t.contains("# Safety");
                } else {
                    break;
                }
            }
            if !ok {
                bad.push(format!("src/{path}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(blocks > 0, "no unsafe found in src/simd/: the layer this rule guards is gone");
    assert!(bad.is_empty(), "unsafe without a SAFETY note:\n{}", bad.join("\n"));
}

#[test]
fn no_file_over_1400_lines_and_every_file_has_a_header() {
    let mut bad = Vec::new();
    for (path, text) in crate::util::crate_sources() {
        let lines = text.lines().count();
        if lines > 1400 {
            bad.push(format!("src/{path}: {lines} lines (at most 1400)"));
        }
        if !text.trim_start().starts_with("//!") {
            bad.push(format!("src/{path}: no //! header"));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

//! The `.vm` reader: one clause a line, `ID OPCODE ARGS...`, IDs of any spelling, `#`
//! comments and blank lines; the last clause is the shape (inside where negative). Every
//! problem is one error naming the line: an unknown opcode, a wrong argument count, an ID
//! used before its definition (which is also how a cycle shows in SSA), an ID defined
//! twice, a constant that is not a finite number.

use std::collections::HashMap;
use std::path::Path;

use super::ops::Opcode;
use super::tape::{Clause, Ssa};
use crate::error::{Error, Location, Result};
use crate::files::read_input_text;

/// Largest `.vm` file read, bytes (prospero.vm is 0.2 MB; 10^6 clauses take about 30 MB).
pub const MAX_VM_BYTES: u64 = 256 << 20;

/// Most clauses in one model (each costs a few tens of bytes to read and evaluate).
pub const MAX_CLAUSES: usize = 8_000_000;

/// Reads the `.vm` file `path`.
///
/// # Errors
/// [`Error::Io`] when it cannot be read or is larger than [`MAX_VM_BYTES`];
/// [`Error::Input`] with the line of the first malformed clause.
pub fn load_vm(path: &Path) -> Result<Ssa> {
    let text = read_input_text(path, MAX_VM_BYTES)?;
    parse_vm(&text, path)
}

/// Parses `.vm` text; `path` names it in errors.
///
/// # Errors
/// As [`load_vm`].
pub fn parse_vm(text: &str, path: &Path) -> Result<Ssa> {
    let mut ids: HashMap<&str, (u32, usize)> = HashMap::new();
    let mut clauses = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let err =
            |column: usize, msg: String| Error::input(path, Some(Location { line: line_no, column }), msg);
        let body = line.split('#').next().unwrap_or("");
        let mut tokens = body.split_whitespace();
        let Some(id) = tokens.next() else { continue };
        let col = |tok: &str| tok.as_ptr() as usize - line.as_ptr() as usize + 1;
        let Some(opname) = tokens.next() else {
            return Err(err(col(id), format!("clause `{}` has no opcode", short(id))));
        };
        let Some(op) = Opcode::parse(opname) else {
            return Err(err(col(opname), format!("unknown opcode `{}`", short(opname))));
        };
        let args: Vec<&str> = tokens.collect();
        let want = if op == Opcode::Const { 1 } else { op.arity() };
        if args.len() != want {
            return Err(err(
                col(opname),
                format!(
                    "`{opname}` takes {want} argument{}, found {}",
                    if want == 1 { "" } else { "s" },
                    args.len()
                ),
            ));
        }
        if let Some(&(_, first)) = ids.get(id) {
            return Err(err(col(id), format!("ID `{}` defined again (first on line {first})", short(id))));
        }
        if clauses.len() >= MAX_CLAUSES {
            return Err(err(1, format!("more than {MAX_CLAUSES} clauses")));
        }
        let mut clause = Clause { op, a: 0, b: 0, value: 0.0 };
        if op == Opcode::Const {
            let v: f64 = args[0]
                .parse()
                .map_err(|_| err(col(args[0]), format!("constant `{}` is not a number", short(args[0]))))?;
            if !v.is_finite() {
                return Err(err(col(args[0]), format!("constant `{}` is not finite", short(args[0]))));
            }
            clause.value = v;
        } else {
            let mut refs = [0u32; 2];
            for (k, &a) in args.iter().enumerate() {
                let Some(&(i, _)) = ids.get(a) else {
                    return Err(err(
                        col(a),
                        format!("ID `{}` is not defined before this use (undefined, or a cycle)", short(a)),
                    ));
                };
                refs[k] = i;
            }
            clause.a = refs[0];
            clause.b = refs[1];
        }
        ids.insert(id, (clauses.len() as u32, line_no));
        clauses.push(clause);
    }
    if clauses.is_empty() {
        return Err(Error::input(path, None, "no clauses (a .vm file needs at least one)"));
    }
    Ok(Ssa { clauses })
}

/// `s`, cut to a readable length for an error message.
fn short(s: &str) -> String {
    if s.chars().count() <= 40 {
        s.to_string()
    } else {
        format!("{}...", s.chars().take(40).collect::<String>())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(text: &str) -> String {
        parse_vm(text, "m.vm".as_ref()).unwrap_err().to_string()
    }

    #[test]
    fn reads_any_id_spelling_constants_and_comments() {
        let ssa = parse_vm(
            "# c\n\n_1f var-x\n0x000000001b const -1.5e-1 # half\nmxy add _1f 0x000000001b\n",
            "m.vm".as_ref(),
        )
        .unwrap();
        assert_eq!(ssa.clauses.len(), 3);
        assert_eq!(ssa.eval_f64([1.0, 0.0, 0.0]), 0.85);
    }

    #[test]
    fn malformed_files_get_one_line_errors_with_the_line() {
        assert_eq!(msg("a var-x\nb frob a\n"), "m.vm:2:3: unknown opcode `frob`");
        assert_eq!(msg("a var-x\nb add a\n"), "m.vm:2:3: `add` takes 2 arguments, found 1");
        assert!(msg("a var-x\nb add a c\n").starts_with("m.vm:2:9: ID `c` is not defined"));
        assert!(msg("a add b b\nb var-x\n").starts_with("m.vm:1:7: ID `b` is not defined"));
        assert_eq!(msg("a var-x\na var-y\n"), "m.vm:2:1: ID `a` defined again (first on line 1)");
        assert_eq!(msg("a const NaN\n"), "m.vm:1:9: constant `NaN` is not finite");
        assert_eq!(msg("a const 1x\n"), "m.vm:1:9: constant `1x` is not a number");
        assert_eq!(msg("a\n"), "m.vm:1:1: clause `a` has no opcode");
        assert_eq!(msg("# nothing\n"), "m.vm: no clauses (a .vm file needs at least one)");
    }

    #[test]
    fn a_million_clauses_read_and_evaluate() {
        let mut s = String::from("x var-x\n");
        for i in 0..1_000_000 {
            let prev = if i == 0 { "x".to_string() } else { format!("_{}", i - 1) };
            s.push_str(&format!("_{i} add {prev} x\n"));
        }
        let ssa = parse_vm(&s, "m.vm".as_ref()).unwrap();
        assert_eq!(ssa.eval_f64([1.0, 0.0, 0.0]), 1_000_001.0);
        let tape = super::super::tape::Tape::allocate(&ssa);
        assert!(tape.registers <= 3);
    }
}

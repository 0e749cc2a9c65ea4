//! The opcodes of the `.vm` format and their scalar meaning, in f64 (the reference) and
//! f32 (the fast path); one function per precision, so every evaluator agrees with them.

/// One opcode of the `.vm` format (Fidget's whole set).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[allow(missing_docs)]
pub enum Opcode {
    VarX,
    VarY,
    VarZ,
    Const,
    Copy,
    Neg,
    Abs,
    Recip,
    Sqrt,
    Square,
    Floor,
    Ceil,
    Round,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Exp,
    Ln,
    Not,
    Add,
    Sub,
    Mul,
    Div,
    Min,
    Max,
    Atan2,
    Mod,
    Compare,
    And,
    Or,
}

impl Opcode {
    /// The opcode spelled `name` in a `.vm` file.
    pub fn parse(name: &str) -> Option<Opcode> {
        use Opcode::*;
        Some(match name {
            "var-x" => VarX,
            "var-y" => VarY,
            "var-z" => VarZ,
            "const" => Const,
            "copy" => Copy,
            "neg" => Neg,
            "abs" => Abs,
            "recip" => Recip,
            "sqrt" => Sqrt,
            "square" => Square,
            "floor" => Floor,
            "ceil" => Ceil,
            "round" => Round,
            "sin" => Sin,
            "cos" => Cos,
            "tan" => Tan,
            "asin" => Asin,
            "acos" => Acos,
            "atan" => Atan,
            "exp" => Exp,
            "ln" => Ln,
            "not" => Not,
            "add" => Add,
            "sub" => Sub,
            "mul" => Mul,
            "div" => Div,
            "min" => Min,
            "max" => Max,
            "atan2" => Atan2,
            "mod" => Mod,
            "compare" => Compare,
            "and" => And,
            "or" => Or,
            _ => return None,
        })
    }

    /// How many value arguments the opcode takes (`const` takes a number instead: 0).
    pub fn arity(self) -> usize {
        use Opcode::*;
        match self {
            VarX | VarY | VarZ | Const => 0,
            Add | Sub | Mul | Div | Min | Max | Atan2 | Mod | Compare | And | Or => 2,
            _ => 1,
        }
    }
}

macro_rules! scalar {
    ($name:ident, $t:ty) => {
        /// The value of a unary or binary opcode (`b` ignored for a unary one); variables and
        /// constants are not computed here.
        #[inline(always)]
        pub fn $name(op: Opcode, a: $t, b: $t) -> $t {
            use Opcode::*;
            match op {
                VarX | VarY | VarZ | Const => a,
                Copy => a,
                Neg => -a,
                Abs => a.abs(),
                Recip => 1.0 / a,
                Sqrt => a.sqrt(),
                Square => a * a,
                Floor => a.floor(),
                Ceil => a.ceil(),
                Round => a.round(),
                Sin => a.sin(),
                Cos => a.cos(),
                Tan => a.tan(),
                Asin => a.asin(),
                Acos => a.acos(),
                Atan => a.atan(),
                Exp => a.exp(),
                Ln => a.ln(),
                Not => {
                    if a.is_nan() {
                        a
                    } else {
                        (a == 0.0) as u8 as $t
                    }
                }
                Add => a + b,
                Sub => a - b,
                Mul => a * b,
                Div => a / b,
                // Fidget's min and max propagate NaN.
                Min => {
                    if a.is_nan() || b.is_nan() {
                        <$t>::NAN
                    } else {
                        a.min(b)
                    }
                }
                Max => {
                    if a.is_nan() || b.is_nan() {
                        <$t>::NAN
                    } else {
                        a.max(b)
                    }
                }
                Atan2 => a.atan2(b),
                Mod => a.rem_euclid(b),
                Compare => {
                    if a.is_nan() || b.is_nan() {
                        <$t>::NAN
                    } else if a < b {
                        -1.0
                    } else if a > b {
                        1.0
                    } else {
                        0.0
                    }
                }
                And => {
                    if a == 0.0 {
                        a
                    } else {
                        b
                    }
                }
                Or => {
                    if a != 0.0 {
                        a
                    } else {
                        b
                    }
                }
            }
        }
    };
}

scalar!(apply_f64, f64);
scalar!(apply_f32, f32);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euclidean_mod_compare_and_logic_follow_fidget() {
        assert_eq!(apply_f64(Opcode::Mod, -1.0, 3.0), 2.0);
        assert_eq!(apply_f64(Opcode::Mod, 7.5, -2.0), 1.5);
        assert_eq!(apply_f64(Opcode::Compare, 1.0, 2.0), -1.0);
        assert_eq!(apply_f64(Opcode::Compare, 2.0, 2.0), 0.0);
        assert_eq!(apply_f64(Opcode::Compare, 3.0, 2.0), 1.0);
        assert_eq!(apply_f64(Opcode::And, 0.0, 5.0), 0.0);
        assert_eq!(apply_f64(Opcode::And, 2.0, 5.0), 5.0);
        assert_eq!(apply_f64(Opcode::Or, 2.0, 5.0), 2.0);
        assert_eq!(apply_f64(Opcode::Or, 0.0, 5.0), 5.0);
        assert_eq!(apply_f64(Opcode::Not, 0.0, 0.0), 1.0);
        assert_eq!(apply_f64(Opcode::Not, 3.0, 0.0), 0.0);
        assert!(apply_f32(Opcode::Min, f32::NAN, 1.0).is_nan());
    }
}

//! The config deserializer's type errors in the user's words: "invalid type: floating point 1e30, expected usize;
//! in meanfield.iterations" says nothing a user knows; "`meanfield.iterations` takes a whole number >= 0 (like 5),
//! not 1e30" does.

/// `msg` (a deserializer's message, on one line) with its type error, if any, said as what the key takes and what it
/// was given; the value as the `--set` item that gave it wrote it, when one did.
pub(super) fn explain_type_error(msg: &str, overrides: &[String]) -> String {
    let Some((before, error)) = ["invalid type: ", "invalid value: "].iter().find_map(|p| msg.split_once(p)) else {
        return msg.to_string();
    };
    let Some((got, rest)) = error.split_once(", expected ") else { return msg.to_string() };
    let (expected, key) = match rest.split_once("; in `") {
        Some((expected, key)) => (expected, key.trim_end_matches('`')),
        None => (rest, ""),
    };
    let takes = match expected.trim() {
        "usize" | "u8" | "u16" | "u32" | "u64" => "a whole number >= 0 (like 5)",
        "isize" | "i8" | "i16" | "i32" | "i64" => "a whole number (like 5)",
        "f32" | "f64" => "a number (like 0.5)",
        "a boolean" => "true or false",
        "string only" | "a string" => "a name (a string)",
        other => other,
    };
    let written = overrides.iter().rev().find_map(|item| {
        let (k, v) = item.split_once('=')?;
        (k.trim() == key && !key.is_empty()).then(|| v.trim().to_string())
    });
    let given = written.unwrap_or_else(|| {
        let quoted = got.split_once('`').and_then(|(_, v)| v.split_once('`')).map(|(v, _)| v.to_string());
        quoted.unwrap_or_else(|| got.trim().trim_start_matches("string ").to_string())
    });
    let subject = if key.is_empty() { "the value".to_string() } else { format!("`{key}`") };
    format!("{before}{subject} takes {takes}, not {given}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_errors_say_what_the_key_takes() {
        let msg = "invalid type: floating point `1000000000000000000000000000000.0`, expected usize; in `meanfield.iterations`";
        let items = ["meanfield.iterations=1e30".to_string()];
        assert_eq!(
            explain_type_error(msg, &items),
            "`meanfield.iterations` takes a whole number >= 0 (like 5), not 1e30"
        );
        assert_eq!(
            explain_type_error(msg, &[]),
            "`meanfield.iterations` takes a whole number >= 0 (like 5), not 1000000000000000000000000000000.0"
        );
        let msg = "invalid type: integer `3`, expected a boolean; in `post.fill`";
        assert_eq!(explain_type_error(msg, &[]), "`post.fill` takes true or false, not 3");
        let msg = "invalid type: string \"x\", expected usize; in `meanfield.iterations`";
        assert_eq!(
            explain_type_error(msg, &[]),
            "`meanfield.iterations` takes a whole number >= 0 (like 5), not \"x\""
        );
        assert_eq!(explain_type_error("unknown field `x`", &[]), "unknown field `x`");
    }
}

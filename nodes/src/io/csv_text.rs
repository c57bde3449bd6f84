//! Writing CSV by hand: one field quoted as RFC 4180 asks, where it has to be.

/// `s` as one CSV field: quoted (with inner quotes doubled) when it holds a comma, a quote or a
/// line break, as is otherwise.
pub fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// `cells` as one CSV line (without its line break), each quoted where it has to be.
pub fn row<S: AsRef<str>>(cells: &[S]) -> String {
    cells
        .iter()
        .map(|c| field(c.as_ref()))
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
mod tests {
    use super::{field, row};

    #[test]
    fn only_fields_that_need_it_are_quoted() {
        assert_eq!(field("KODAMA twin"), "KODAMA twin");
        assert_eq!(field("a,b"), "\"a,b\"");
        assert_eq!(field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(field("two\nlines"), "\"two\nlines\"");
        assert_eq!(row(&["a", "b,c", ""]), "a,\"b,c\",");
    }
}

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

#[cfg(test)]
mod tests {
    use super::field;

    #[test]
    fn only_fields_that_need_it_are_quoted() {
        assert_eq!(field("KODAMA twin"), "KODAMA twin");
        assert_eq!(field("a,b"), "\"a,b\"");
        assert_eq!(field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(field("two\nlines"), "\"two\nlines\"");
    }
}

//! A recursive-descent parser for the RON subset graph files use: structs (named or anonymous),
//! tuples, lists, maps, strings, numbers, booleans, chars, identifiers, `//` and `/* */` comments.

use super::{Ast, Name, Span, Value};

/// A syntax error and where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct ParseError {
    /// Where the parser stopped.
    pub span: Span,
    /// What it expected and found.
    pub message: String,
}

/// How deep lists, maps, tuples and structs may nest. Graphs nest a handful of levels; the limit
/// keeps the parser, the deserializer and every walk over the tree (all recursive) far from the
/// end of the stack on any input.
pub const MAX_DEPTH: usize = 128;

/// Parses one RON value from `text`; `src` tags the spans, `line`/`col` are where `text` starts.
pub fn parse(text: &str, src: u16, line: u32, col: u32) -> Result<Ast, ParseError> {
    let mut p = Parser {
        chars: text.chars().collect(),
        pos: 0,
        src,
        line,
        col,
        depth: 0,
    };
    let v = p.value()?;
    p.skip_ws()?;
    if p.pos < p.chars.len() {
        return Err(p.error(format!("expected the end of input, found {}", p.found())));
    }
    Ok(v)
}

struct Parser {
    chars: Vec<char>,
    pos: usize,
    src: u16,
    line: u32,
    col: u32,
    /// Values being parsed around the current one.
    depth: usize,
}

impl Parser {
    fn span(&self) -> Span {
        Span {
            src: self.src,
            line: self.line,
            col: self.col,
        }
    }
    fn error(&self, message: String) -> ParseError {
        ParseError {
            span: self.span(),
            message,
        }
    }
    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }
    fn peek_at(&self, k: usize) -> Option<char> {
        self.chars.get(self.pos + k).copied()
    }
    fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.pos += 1;
        if c == '\n' {
            self.line += 1;
            self.col = 1;
        } else {
            self.col += 1;
        }
        Some(c)
    }
    fn found(&self) -> String {
        match self.peek() {
            None => "the end of input".into(),
            Some(c) => format!("`{c}`"),
        }
    }

    fn skip_ws(&mut self) -> Result<(), ParseError> {
        loop {
            match (self.peek(), self.peek_at(1)) {
                (Some(c), _) if c.is_whitespace() => {
                    self.bump();
                }
                (Some('/'), Some('/')) => {
                    while self.peek().is_some_and(|c| c != '\n') {
                        self.bump();
                    }
                }
                (Some('/'), Some('*')) => {
                    let start = self.span();
                    self.bump();
                    self.bump();
                    let mut depth = 1;
                    while depth > 0 {
                        match (self.bump(), self.peek()) {
                            (None, _) => {
                                return Err(ParseError {
                                    span: start,
                                    message: "unterminated block comment".into(),
                                });
                            }
                            (Some('*'), Some('/')) => {
                                self.bump();
                                depth -= 1;
                            }
                            (Some('/'), Some('*')) => {
                                self.bump();
                                depth += 1;
                            }
                            _ => {}
                        }
                    }
                }
                _ => return Ok(()),
            }
        }
    }

    fn expect(&mut self, ch: char) -> Result<(), ParseError> {
        self.skip_ws()?;
        if self.peek() == Some(ch) {
            self.bump();
            Ok(())
        } else {
            Err(self.error(format!("expected `{ch}`, found {}", self.found())))
        }
    }

    fn value(&mut self) -> Result<Ast, ParseError> {
        if self.depth >= MAX_DEPTH {
            return Err(self.error(format!(
                "values nested more than {MAX_DEPTH} levels deep; a graph needs far fewer"
            )));
        }
        self.depth += 1;
        let v = self.value_at_depth();
        self.depth -= 1;
        v
    }

    fn value_at_depth(&mut self) -> Result<Ast, ParseError> {
        self.skip_ws()?;
        let span = self.span();
        let v = match self.peek() {
            None => return Err(self.error("expected a value, found the end of input".into())),
            Some('"') => Value::Str(self.string()?),
            Some('\'') => Value::Char(self.char_lit()?),
            Some('[') => {
                self.bump();
                Value::List(self.items(']')?)
            }
            Some('{') => {
                self.bump();
                Value::Map(self.map_entries()?)
            }
            Some('(') => {
                self.bump();
                self.paren_body(None)?
            }
            Some(c) if c == '-' || c == '+' || c == '.' || c.is_ascii_digit() => self.number()?,
            Some(c) if c.is_alphabetic() || c == '_' => {
                let name = self.ident();
                match name.as_str() {
                    "true" => Value::Bool(true),
                    "false" => Value::Bool(false),
                    "inf" => Value::Float(f64::INFINITY),
                    "NaN" => Value::Float(f64::NAN),
                    _ => {
                        // A name directly followed by `(` is a struct, tuple struct or variant.
                        if self.peek() == Some('(') {
                            self.bump();
                            self.paren_body(Some(Name { name, span }))?
                        } else {
                            Value::Ident(name)
                        }
                    }
                }
            }
            Some(c) => return Err(self.error(format!("expected a value, found `{c}`"))),
        };
        Ok(Ast { v, span })
    }

    fn ident(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek().filter(|c| c.is_alphanumeric() || *c == '_') {
            s.push(c);
            self.bump();
        }
        s
    }

    /// After `(`: a struct body `a: 1, b: 2)`, a tuple `1, 2)`, or `)`.
    fn paren_body(&mut self, name: Option<Name>) -> Result<Value, ParseError> {
        self.skip_ws()?;
        let is_struct = {
            let save = (self.pos, self.line, self.col);
            let starts_ident = self.peek().is_some_and(|c| c.is_alphabetic() || c == '_');
            let answer = starts_ident && {
                self.ident();
                self.skip_ws()?;
                self.peek() == Some(':')
            };
            (self.pos, self.line, self.col) = save;
            answer
        };
        if is_struct {
            let mut fields: Vec<(Name, Ast)> = Vec::new();
            loop {
                self.skip_ws()?;
                if self.peek() == Some(')') {
                    self.bump();
                    break;
                }
                let fspan = self.span();
                if !self.peek().is_some_and(|c| c.is_alphabetic() || c == '_') {
                    return Err(
                        self.error(format!("expected a field name, found {}", self.found()))
                    );
                }
                let fname = self.ident();
                if fields.iter().any(|(n, _)| n.name == fname) {
                    return Err(ParseError {
                        span: fspan,
                        message: format!("field `{fname}` is given twice"),
                    });
                }
                self.expect(':')?;
                let v = self.value()?;
                fields.push((
                    Name {
                        name: fname,
                        span: fspan,
                    },
                    v,
                ));
                if !self.comma_or_close(')')? {
                    break;
                }
            }
            return Ok(Value::Struct { name, fields });
        }
        let items = self.items(')')?;
        Ok(match name {
            Some(name) if items.is_empty() => Value::Struct {
                name: Some(name),
                fields: Vec::new(),
            },
            Some(name) => Value::Call { name, args: items },
            None if items.is_empty() => Value::Unit,
            None => Value::Tuple(items),
        })
    }

    /// True if another element follows; false after consuming the closing delimiter.
    fn comma_or_close(&mut self, close: char) -> Result<bool, ParseError> {
        self.skip_ws()?;
        match self.peek() {
            Some(',') => {
                self.bump();
                Ok(true)
            }
            Some(c) if c == close => {
                self.bump();
                Ok(false)
            }
            _ => Err(self.error(format!("expected `,` or `{close}`, found {}", self.found()))),
        }
    }

    fn items(&mut self, close: char) -> Result<Vec<Ast>, ParseError> {
        let mut out = Vec::new();
        loop {
            self.skip_ws()?;
            if self.peek() == Some(close) {
                self.bump();
                return Ok(out);
            }
            out.push(self.value()?);
            if !self.comma_or_close(close)? {
                return Ok(out);
            }
        }
    }

    fn map_entries(&mut self) -> Result<Vec<(Ast, Ast)>, ParseError> {
        let mut out: Vec<(Ast, Ast)> = Vec::new();
        // Keys by their RON text: a hash lookup, so a map of 50,000 nodes is checked in linear time.
        let mut keys = std::collections::HashSet::new();
        loop {
            self.skip_ws()?;
            if self.peek() == Some('}') {
                self.bump();
                return Ok(out);
            }
            let k = self.value()?;
            if !keys.insert(k.to_ron()) {
                return Err(ParseError {
                    span: k.span,
                    message: format!("map key {} is given twice", k.v.describe()),
                });
            }
            self.expect(':')?;
            let v = self.value()?;
            out.push((k, v));
            if !self.comma_or_close('}')? {
                return Ok(out);
            }
        }
    }

    fn string(&mut self) -> Result<String, ParseError> {
        let start = self.span();
        self.bump();
        let mut s = String::new();
        loop {
            match self.bump() {
                None => {
                    return Err(ParseError {
                        span: start,
                        message: "unterminated string".into(),
                    });
                }
                Some('"') => return Ok(s),
                Some('\\') => s.push(self.escape()?),
                Some(c) => s.push(c),
            }
        }
    }

    fn char_lit(&mut self) -> Result<char, ParseError> {
        self.bump();
        let c = match self.bump() {
            Some('\\') => self.escape()?,
            Some(c) => c,
            None => return Err(self.error("unterminated char literal".into())),
        };
        if self.bump() != Some('\'') {
            return Err(self.error("expected `'` to close the char literal".into()));
        }
        Ok(c)
    }

    fn escape(&mut self) -> Result<char, ParseError> {
        Ok(match self.bump() {
            Some('n') => '\n',
            Some('t') => '\t',
            Some('r') => '\r',
            Some('0') => '\0',
            Some('\\') => '\\',
            Some('"') => '"',
            Some('\'') => '\'',
            Some('u') => {
                self.expect('{')?;
                let mut hex = String::new();
                while let Some(c) = self.peek().filter(|c| c.is_ascii_hexdigit()) {
                    hex.push(c);
                    self.bump();
                }
                self.expect('}')?;
                u32::from_str_radix(&hex, 16)
                    .ok()
                    .and_then(char::from_u32)
                    .ok_or_else(|| self.error(format!("invalid unicode escape `{hex}`")))?
            }
            other => return Err(self.error(format!("unknown escape `\\{}`", other.unwrap_or(' ')))),
        })
    }

    fn number(&mut self) -> Result<Value, ParseError> {
        let start = self.span();
        let mut s = String::new();
        if let Some(sign) = self.peek().filter(|c| *c == '-' || *c == '+') {
            s.push(sign);
            self.bump();
        }
        if self.peek().is_some_and(|c| c.is_alphabetic()) {
            let word = self.ident();
            return match word.as_str() {
                "inf" => Ok(Value::Float(if s == "-" {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                })),
                _ => Err(ParseError {
                    span: start,
                    message: format!("expected a number, found `{s}{word}`"),
                }),
            };
        }
        let mut is_float = false;
        while let Some(c) = self.peek() {
            let exp_sign = (c == '-' || c == '+') && s.ends_with(['e', 'E']);
            if c.is_ascii_digit() || c == '_' || exp_sign {
                if c != '_' {
                    s.push(c);
                }
            } else if c == '.' || c == 'e' || c == 'E' {
                is_float = true;
                s.push(c);
            } else {
                break;
            }
            self.bump();
        }
        let bad = || ParseError {
            span: start,
            message: format!("expected a number, found `{s}`"),
        };
        if is_float {
            s.parse::<f64>().map(Value::Float).map_err(|_| bad())
        } else {
            s.parse::<i128>().map(Value::Int).map_err(|_| bad())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Value {
        parse(s, 0, 1, 1).unwrap().v
    }

    #[test]
    fn values() {
        assert_eq!(p("42"), Value::Int(42));
        assert_eq!(p("-1.5e2"), Value::Float(-150.0));
        assert_eq!(p("\"a\\\"b\""), Value::Str("a\"b".into()));
        assert_eq!(p("Max"), Value::Ident("Max".into()));
        assert_eq!(p("()"), Value::Unit);
        assert!(matches!(p("(1.0, 2)"), Value::Tuple(v) if v.len() == 2));
        assert!(matches!(p("Some(3)"), Value::Call { args, .. } if args.len() == 1));
        assert!(matches!(p("[1, 2, ]"), Value::List(v) if v.len() == 2));
        assert!(matches!(p("{\"a\": 1}"), Value::Map(v) if v.len() == 1));
    }

    #[test]
    fn structs_with_comments_and_spans() {
        let a = parse(
            "// top\nSite(\n  crs: \"EPSG:1\", /* c */ cell_m: 0.5,\n)",
            0,
            1,
            1,
        )
        .unwrap();
        assert_eq!(
            a.span,
            Span {
                src: 0,
                line: 2,
                col: 1
            }
        );
        let Value::Struct { name, fields } = a.v else {
            panic!()
        };
        assert_eq!(name.unwrap().name, "Site");
        assert_eq!(fields[1].0.name, "cell_m");
        assert_eq!(
            fields[1].0.span,
            Span {
                src: 0,
                line: 3,
                col: 26
            }
        );
        assert_eq!(fields[1].1.span.col, 34);
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let deep = "[".repeat(100_000);
        let e = parse(&deep, 0, 1, 1).unwrap_err();
        assert_eq!(e.span.col, MAX_DEPTH as u32 + 1);
        assert!(e.message.contains("nested more than"), "{}", e.message);
        let ok = format!("{}{}", "[".repeat(MAX_DEPTH), "]".repeat(MAX_DEPTH));
        parse(&ok, 0, 1, 1).unwrap();
    }

    #[test]
    fn errors_have_positions() {
        let e = parse("Graph(\n  a: 1,\n  b: ,\n)", 0, 1, 1).unwrap_err();
        assert_eq!((e.span.line, e.span.col), (3, 6));
        assert!(e.message.contains("expected a value"), "{}", e.message);
        let e = parse("(a: 1, a: 2)", 0, 1, 1).unwrap_err();
        assert!(e.message.contains("given twice"));
    }
}

//! Two jobs before the crate compiles:
//!
//! - The params reference (`params::reference`): every type in `src/` that derives `Deserialize`
//!   (stages' params and the structs and enums inside them), with each field's type, whether it
//!   may be left out, and its doc comment, read from the source with syn. `kodama-dag kinds KIND`
//!   prints it, so the reference is the code's own documentation and cannot drift from it.
//! - Under feature `cuda`: compiles the GPU kernels' source (src/rf/gpu/kernels.cu) for the host
//!   with g++, so that the tests can run the very code the GPU runs against the Rust tracer on a
//!   machine without a GPU. `-ffp-contract=off` keeps g++ from fusing multiply-adds, as NVRTC's
//!   `--fmad=false` keeps the GPU from it: the same IEEE operations on both.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use quote::ToTokens;

fn main() {
    #[cfg(feature = "cuda")]
    {
        println!("cargo:rerun-if-changed=src/rf/gpu/kernels.cu");
        cc::Build::new()
            .cpp(true)
            .file("src/rf/gpu/kernels.cu")
            // g++ would otherwise take the .cu file for a linker input.
            .flag("-x")
            .flag("c++")
            .flag("-std=c++14")
            .flag("-ffp-contract=off")
            .flag("-fno-fast-math")
            .flag("-fno-exceptions")
            .opt_level(2)
            .warnings(false)
            .compile("kodama_gpu_host");
    }
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src");
    write_params_reference();
}

/// One documented type, as Rust source for `params::reference::TYPES`.
struct TypeDoc {
    module: String,
    name: String,
    doc: String,
    /// A struct's fields, or an enum's variants (each a "field" whose type is its payload).
    fields: Vec<FieldDoc>,
    is_enum: bool,
}

struct FieldDoc {
    name: String,
    ty: String,
    doc: String,
    optional: bool,
}

fn write_params_reference() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut types = Vec::new();
    for file in &files {
        let Ok(text) = std::fs::read_to_string(file) else {
            continue;
        };
        // A file that does not parse fails the crate's own build with a better message.
        let Ok(parsed) = syn::parse_file(&text) else {
            continue;
        };
        let module = module_path(&src, file);
        collect(&parsed.items, &module, &mut types);
    }
    let mut out = String::from("&[\n");
    for t in &types {
        let _ = writeln!(
            out,
            "    TypeDoc {{ module: {:?}, name: {:?}, doc: {:?}, is_enum: {}, fields: &[",
            t.module, t.name, t.doc, t.is_enum
        );
        for f in &t.fields {
            let _ = writeln!(
                out,
                "        FieldDoc {{ name: {:?}, ty: {:?}, doc: {:?}, optional: {} }},",
                f.name, f.ty, f.doc, f.optional
            );
        }
        out.push_str("    ] },\n");
    }
    out.push(']');
    let dest = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"))
        .join("params_reference.rs");
    std::fs::write(dest, out).expect("OUT_DIR is writable");
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `src/stages/radio/radio_map.rs` -> `kodama_nodes::stages::radio::radio_map`.
fn module_path(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap_or(file).with_extension("");
    let mut parts = vec!["kodama_nodes".to_string()];
    for c in rel.components() {
        let s = c.as_os_str().to_string_lossy().to_string();
        if s != "lib" && s != "mod" {
            parts.push(s);
        }
    }
    parts.join("::")
}

fn collect(items: &[syn::Item], module: &str, out: &mut Vec<TypeDoc>) {
    for item in items {
        match item {
            syn::Item::Struct(s) if derives_deserialize(&s.attrs) => {
                let container_default = serde_attr(&s.attrs, "default").is_some();
                let fields = match &s.fields {
                    syn::Fields::Named(named) => named
                        .named
                        .iter()
                        .map(|f| field_doc(f, container_default))
                        .collect(),
                    _ => Vec::new(),
                };
                out.push(TypeDoc {
                    module: module.to_string(),
                    name: s.ident.to_string(),
                    doc: doc_of(&s.attrs),
                    fields,
                    is_enum: false,
                });
            }
            syn::Item::Enum(e) if derives_deserialize(&e.attrs) => {
                let lowercase =
                    serde_attr(&e.attrs, "rename_all").flatten().as_deref() == Some("lowercase");
                let fields = e
                    .variants
                    .iter()
                    .map(|v| {
                        let name = v.ident.to_string();
                        FieldDoc {
                            name: if lowercase { name.to_lowercase() } else { name },
                            ty: payload(&v.fields),
                            doc: doc_of(&v.attrs),
                            optional: false,
                        }
                    })
                    .collect();
                out.push(TypeDoc {
                    module: module.to_string(),
                    name: e.ident.to_string(),
                    doc: doc_of(&e.attrs),
                    fields,
                    is_enum: true,
                });
            }
            syn::Item::Mod(m) => {
                if let Some((_, inner)) = &m.content {
                    collect(inner, &format!("{module}::{}", m.ident), out);
                }
            }
            _ => {}
        }
    }
}

/// A variant's payload as a graph writes it: `(f64)`, `(alpha_r: u32)`, or nothing.
fn payload(fields: &syn::Fields) -> String {
    let ty = |f: &syn::Field| tidy(&f.ty.to_token_stream().to_string());
    match fields {
        syn::Fields::Unit => String::new(),
        syn::Fields::Unnamed(u) => {
            let parts: Vec<String> = u.unnamed.iter().map(ty).collect();
            format!("({})", parts.join(", "))
        }
        syn::Fields::Named(n) => {
            let parts: Vec<String> = n
                .named
                .iter()
                .map(|f| {
                    let name = f.ident.as_ref().map(|i| i.to_string()).unwrap_or_default();
                    format!("{name}: {}", ty(f))
                })
                .collect();
            format!("({})", parts.join(", "))
        }
    }
}

fn field_doc(f: &syn::Field, container_default: bool) -> FieldDoc {
    let ty = tidy(&f.ty.to_token_stream().to_string());
    // serde fills a missing Option with None, and a field marked default with its default.
    let optional =
        container_default || serde_attr(&f.attrs, "default").is_some() || ty.starts_with("Option<");
    FieldDoc {
        name: f
            .ident
            .as_ref()
            .map(|i| i.to_string().trim_start_matches("r#").to_string())
            .unwrap_or_default(),
        ty,
        doc: doc_of(&f.attrs),
        optional,
    }
}

/// A type's tokens as a person writes them: `(f64 , f64)` -> `(f64, f64)`.
fn tidy(s: &str) -> String {
    s.replace(" ,", ",")
        .replace("< ", "<")
        .replace(" <", "<")
        .replace(" >", ">")
        .replace("( ", "(")
        .replace(" )", ")")
        .replace("[ ", "[")
        .replace(" ]", "]")
        .replace(" ;", ";")
        .replace(" :: ", "::")
        .replace("& ", "&")
}

fn derives_deserialize(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("derive") && a.to_token_stream().to_string().contains("Deserialize")
    })
}

/// The doc comment, its lines joined as one paragraph per blank line.
fn doc_of(attrs: &[syn::Attribute]) -> String {
    let mut lines = Vec::new();
    for a in attrs {
        if let syn::Meta::NameValue(nv) = &a.meta
            && nv.path.is_ident("doc")
            && let syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) = &nv.value
        {
            lines.push(s.value().trim().to_string());
        }
    }
    lines.join("\n")
}

/// `#[serde(..., name, ...)]`: None when absent, `Some(None)` as a bare word (`default`),
/// `Some(Some(v))` with a string value (`default = "five"`, `rename_all = "lowercase"`).
fn serde_attr(attrs: &[syn::Attribute], name: &str) -> Option<Option<String>> {
    let mut found = None;
    for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
        let _ = a.parse_nested_meta(|m| {
            let this = m.path.is_ident(name);
            if m.input.peek(syn::Token![=]) {
                let v: syn::Expr = m.value()?.parse()?;
                if this {
                    found = Some(match v {
                        syn::Expr::Lit(syn::ExprLit {
                            lit: syn::Lit::Str(s),
                            ..
                        }) => Some(s.value()),
                        _ => None,
                    });
                }
            } else if m.input.peek(syn::token::Paren) {
                let content;
                syn::parenthesized!(content in m.input);
                let _: proc_macro2::TokenStream = content.parse()?;
            } else if this {
                found = Some(None);
            }
            Ok(())
        });
    }
    found
}

//! docs/configuration.md's table of every setting, rendered from the
//! settings rows, so the document cannot drift from the flags: the config
//! module's test fails when the file differs from the rendering, and
//! rewrites it when run with `INBETWEEN_BLESS=1` (the command is [`BLESS`]).

/// The command that rewrites the table (CONTRIBUTING.md, "Tests").
pub const BLESS: &str = "INBETWEEN_BLESS=1 cargo test -p inbetween-server --lib configuration_doc";

/// Where the generated table starts and ends in the document.
const BEGIN: &str = "<!-- Generated from the settings rows in crates/server/src/config.rs: INBETWEEN_BLESS=1 cargo test \
                     -p inbetween-server --lib configuration_doc -->";
const END: &str = "<!-- End of the generated table. -->";

/// A row's default as the document shows it.
pub enum Default {
    /// Words (`one per core`, `none`) or a path, as the row's `shown` says.
    Shown(&'static str),
    /// The default value, shown as code.
    Value(String),
    None,
}

/// One setting as the document's table shows it.
pub struct Row {
    /// `""` for the top level, else the TOML table (`limits`).
    pub table: &'static str,
    pub toml: &'static str,
    pub flag: &'static str,
    pub env: &'static str,
    pub value: &'static str,
    /// The row's type as written (`Vec<…>`: repeatable on the command line,
    /// comma-separated in the environment, a TOML array: of strings, or of tables).
    pub ty: &'static str,
    pub default: Default,
    pub meaning: &'static str,
}

impl Row {
    fn markdown(&self) -> String {
        let value = if self.value == "BOOL" { "[BOOL]".to_owned() } else { self.value.to_owned() };
        let key = if self.table.is_empty() { self.toml.to_owned() } else { format!("[{}] {}", self.table, self.toml) };
        let (flag, env, key) = if let Some(item) = self.ty.strip_prefix("Vec") {
            let key = if item.contains("String") { format!("`{key} = [..]`") } else { format!("`[[{key}]]` tables") };
            (format!("`--{} {value}` (repeatable)", self.flag), format!("`{}` (comma-separated)", self.env), key)
        } else {
            (format!("`--{} {value}`", self.flag), format!("`{}`", self.env), format!("`{key}`"))
        };
        let meaning = self.meaning.replace('|', "\\|");
        format!("| {flag} | {env} | {key} | {} | {meaning} |", self.default_text())
    }

    fn default_text(&self) -> String {
        match &self.default {
            Default::Shown(words) if words.contains(' ') || *words == "none" => (*words).to_owned(),
            Default::Shown(value) => format!("`{value}`"),
            Default::Value(value) if self.value == "BYTES" => {
                let per = if self.toml.ends_with("_per_sec") { "/s" } else { "" };
                format!("`{value}`{}", binary_size(value, per))
            }
            Default::Value(value) => format!("`{value}`"),
            Default::None => "none".to_owned(),
        }
    }
}

/// ` (16 MiB)` for a whole number of MiB or KiB (`per` after the unit), else nothing.
fn binary_size(value: &str, per: &str) -> String {
    match value.parse::<u64>() {
        Ok(n) if n >= 1 << 20 && n % (1 << 20) == 0 => format!(" ({} MiB{per})", n >> 20),
        Ok(n) if n >= 1 << 10 && n % (1 << 10) == 0 => format!(" ({} KiB{per})", n >> 10),
        _ => String::new(),
    }
}

/// The table, one row per setting in the order of the rows.
pub fn table(rows: &[Row]) -> String {
    let mut out =
        String::from("| flag | environment variable | TOML key | default | meaning |\n|---|---|---|---|---|\n");
    for row in rows {
        out.push_str(&row.markdown());
        out.push('\n');
    }
    out
}

/// `doc` with the text between its markers replaced by the table.
pub fn render(doc: &str, rows: &[Row]) -> String {
    let (Some(begin), Some(end)) = (doc.find(BEGIN), doc.find(END)) else {
        panic!("docs/configuration.md lacks the table's markers:\n{BEGIN}\n{END}")
    };
    format!("{}{BEGIN}\n{}{}", &doc[..begin], table(rows), &doc[end..])
}

#[test]
fn sizes_read_as_binary_units() {
    assert_eq!(binary_size("16777216", ""), " (16 MiB)");
    assert_eq!(binary_size("131072", "/s"), " (128 KiB/s)");
    assert_eq!(binary_size("1000", ""), "");
}

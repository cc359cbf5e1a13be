//! A place in a document (a clip, a motion, an IK list) as the core names
//! it: field names, indices and user keys, outermost first. The edge
//! renders it as a JSON pointer (`/tracks/3/times/5`) without the core
//! knowing JSON.

use std::fmt;

/// One step of a path into a clip document.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    Field(&'static str),
    Index(usize),
    /// A key of a JSON object given by the user (a mask's joint name).
    Key(String),
}

/// A place in a clip document, outermost first.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Path(pub Vec<Step>);

impl Path {
    /// The document itself (`/`).
    pub fn root() -> Self {
        Path(Vec::new())
    }

    /// This path, then field `name`.
    pub fn field(mut self, name: &'static str) -> Self {
        self.0.push(Step::Field(name));
        self
    }

    /// This path, then list index `i`.
    pub fn index(mut self, i: usize) -> Self {
        self.0.push(Step::Index(i));
        self
    }

    /// This path, then map key `key`.
    pub fn key(mut self, key: &str) -> Self {
        self.0.push(Step::Key(key.to_owned()));
        self
    }

    /// `/tracks/3/times/5` (RFC 6901).
    pub fn to_pointer(&self) -> String {
        let mut s = String::new();
        for step in &self.0 {
            s.push('/');
            match step {
                Step::Field(f) => s.push_str(f),
                Step::Index(i) => s.push_str(&i.to_string()),
                // RFC 6901: `~` is `~0`, `/` is `~1`.
                Step::Key(k) => s.push_str(&k.replace('~', "~0").replace('/', "~1")),
            }
        }
        s
    }
}

impl fmt::Display for Path {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() { f.write_str("/") } else { f.write_str(&self.to_pointer()) }
    }
}

//! `filmstrips/index.json`: the filmstrips a `rank` run wrote, listed for its report.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::RunError;

/// One filmstrip: its PNG (a file name in `filmstrips/`) and its caption.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Filmstrip {
    /// The PNG's file name.
    pub png: String,
    /// What it shows (policy, seed, both branches' scores).
    pub caption: String,
}

/// Reads an index.
///
/// # Errors
/// [`RunError::Io`] when it cannot be read; [`RunError::Index`] naming the entry and
/// field where it stops being a list of filmstrips.
pub fn read(path: &Path) -> Result<Vec<Filmstrip>, RunError> {
    crate::config::read_typed(path, |field, source| RunError::Index {
        path: path.to_path_buf(),
        field,
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_index_reads_back_and_a_bad_entry_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("index.json");
        let list = vec![Filmstrip { png: "a.png".into(), caption: "policy a".into() }];
        crate::config::write(&path, &list).unwrap();
        assert_eq!(read(&path).unwrap(), list);
        std::fs::write(&path, r#"[{"png": "a.png", "caption": "a"}, {"png": "b.png"}]"#).unwrap();
        let err = read(&path).unwrap_err().to_string();
        assert!(err.contains("[1]") && err.contains("missing field `caption`"), "{err}");
    }
}

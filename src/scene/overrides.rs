//! `--set key.path=value`: changes one value of the parsed YAML before it is checked.

use serde::de::DeserializeOwned;
use serde_yaml_ng::Value;

use super::SceneError;

/// Why [`deserialize_with_overrides`] failed.
#[derive(Debug)]
pub enum YamlProblem {
    /// The text is not YAML, or does not fit the type: `path: message` (the message alone
    /// for the whole document).
    Parse(String),
    /// An assignment could not be applied.
    Override(SceneError),
}

/// Deserializes YAML `text` after applying the `key.path=value` assignments in order. Without
/// assignments it reads the text directly, so that errors carry line and column.
pub fn deserialize_with_overrides<T: DeserializeOwned>(
    text: &str,
    overrides: &[String],
) -> Result<T, YamlProblem> {
    let parse = |path: String, message: String| {
        YamlProblem::Parse(if path == "." {
            message
        } else {
            format!("{path}: {message}")
        })
    };
    if overrides.is_empty() {
        let de = serde_yaml_ng::Deserializer::from_str(text);
        return serde_path_to_error::deserialize(de)
            .map_err(|e| parse(e.path().to_string(), e.inner().to_string()));
    }
    let mut value: Value =
        serde_yaml_ng::from_str(text).map_err(|e| parse(".".into(), e.to_string()))?;
    for assignment in overrides {
        apply(&mut value, assignment).map_err(YamlProblem::Override)?;
    }
    serde_path_to_error::deserialize(value)
        .map_err(|e| parse(e.path().to_string(), e.inner().to_string()))
}

/// Applies `key.path=value` to a YAML document. Path segments are map keys, or indices into
/// sequences; missing map keys are created (unknown ones are then rejected by the parser).
/// The value is parsed as YAML, so `1e-3`, `true`, `[0, 0, 1]` and `{friction: 0.5}` work.
pub fn apply(doc: &mut Value, assignment: &str) -> Result<(), SceneError> {
    let fail = |message: String| SceneError::Override {
        assignment: assignment.into(),
        message,
    };
    let (path, raw) = assignment
        .split_once('=')
        .ok_or_else(|| fail("expected key.path=value".into()))?;
    let value: Value =
        serde_yaml_ng::from_str(raw).map_err(|e| fail(format!("value is not YAML: {e}")))?;
    let mut node = doc;
    let segments: Vec<&str> = path.split('.').collect();
    if segments.iter().any(|s| s.is_empty()) {
        return Err(fail("empty key in path".into()));
    }
    for (depth, segment) in segments.iter().enumerate() {
        let so_far = segments[..=depth].join(".");
        node = match node {
            Value::Mapping(map) => map
                .entry(Value::String(segment.to_string()))
                .or_insert(Value::Mapping(Default::default())),
            Value::Sequence(seq) => {
                let index: usize = segment
                    .parse()
                    .map_err(|_| fail(format!("{so_far}: expected an index into a list")))?;
                let len = seq.len();
                seq.get_mut(index)
                    .ok_or_else(|| fail(format!("{so_far}: index out of range (list has {len})")))?
            }
            Value::Null => {
                *node = Value::Mapping(Default::default());
                match node {
                    Value::Mapping(map) => map
                        .entry(Value::String(segment.to_string()))
                        .or_insert(Value::Mapping(Default::default())),
                    _ => unreachable!(),
                }
            }
            _ => return Err(fail(format!("{so_far}: the parent is not a map or a list"))),
        };
    }
    *node = value;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_nested_values_and_list_items() {
        let mut doc: Value =
            serde_yaml_ng::from_str("a: {b: 1}\nlist: [{x: 1}, {x: 2}]\nempty:\n").unwrap();
        apply(&mut doc, "a.b=2.5").unwrap();
        apply(&mut doc, "a.c=[1, 2]").unwrap();
        apply(&mut doc, "list.1.x=7").unwrap();
        apply(&mut doc, "empty.k=true").unwrap();
        assert_eq!(doc["a"]["b"], Value::from(2.5));
        assert_eq!(doc["a"]["c"][1], Value::from(2));
        assert_eq!(doc["list"][1]["x"], Value::from(7));
        assert_eq!(doc["empty"]["k"], Value::from(true));
        assert!(apply(&mut doc, "list.5.x=1").is_err());
        assert!(apply(&mut doc, "a.b.c=1").is_err());
        assert!(apply(&mut doc, "novalue").is_err());
    }
}

//! RIHS01 type description hashes (REP 2011), as rosbag2 Jazzy records them per topic in
//! `type_description_hash` and `ros2 topic info -v` shows them.
//!
//! The hash is the SHA-256 of the JSON of the type's description (its fields and, sorted by
//! name, every type it refers to), with default values and constants left out, in the key order
//! and `", "`/`": "` separators of `rosidl_generator_type_description`.

use crate::msgs::MessageType;

/// `FIELD_TYPE_NESTED_TYPE` of `type_description_interfaces/msg/FieldType`.
const FIELD_TYPE_NESTED: u8 = 1;
/// Added to a type id for a fixed-size array `T[N]`.
const FIELD_TYPE_ARRAY_OFFSET: u8 = 48;
/// Added to a type id for a bounded sequence `T[<=N]`.
const FIELD_TYPE_BOUNDED_SEQUENCE_OFFSET: u8 = 96;
/// Added to a type id for an unbounded sequence `T[]`.
const FIELD_TYPE_UNBOUNDED_SEQUENCE_OFFSET: u8 = 144;
/// `FIELD_TYPE_BOUNDED_STRING` (`string<=N`).
const FIELD_TYPE_BOUNDED_STRING: u8 = 21;
/// `FIELD_TYPE_BOUNDED_WSTRING` (`wstring<=N`).
const FIELD_TYPE_BOUNDED_WSTRING: u8 = 22;
/// The member rosidl gives a message without fields.
const EMPTY_STRUCT_MEMBER: &str = "structure_needs_at_least_one_member";

/// `type_description_interfaces/msg/FieldType` id of a primitive `.msg` type.
fn primitive_type_id(name: &str) -> Option<u8> {
    Some(match name {
        "int8" => 2,
        "uint8" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "char" => 13,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        "wstring" => 18,
        _ => return None,
    })
}

/// The RIHS01 hash of `ty` (`RIHS01_` and 64 hex digits), or `None` if its definition uses a
/// type it cannot resolve (a nested type missing from `dependencies`, an unknown primitive).
pub fn type_description_hash(ty: &MessageType) -> Option<String> {
    let mut referenced: Vec<(String, String)> = Vec::new();
    let main = describe(ty, &mut referenced)?;
    referenced.sort();
    let refs: Vec<&str> = referenced.iter().map(|(_, json)| json.as_str()).collect();
    let json = format!(
        "{{\"type_description\": {main}, \"referenced_type_descriptions\": [{}]}}",
        refs.join(", ")
    );
    Some(format!("RIHS01_{}", sha256_hex(json.as_bytes())))
}

/// The JSON of `ty`'s individual description; adds every type it refers to (transitively,
/// once each) to `referenced` as (full name, JSON).
fn describe(ty: &MessageType, referenced: &mut Vec<(String, String)>) -> Option<String> {
    let mut fields = Vec::new();
    for line in ty.definition.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let (Some(type_word), Some(name)) = (words.next(), words.next()) else {
            continue;
        };
        if name.contains('=') || words.next() == Some("=") || type_word.contains('=') {
            continue; // a constant
        }
        fields.push(field_json(ty, type_word, name, referenced)?);
    }
    if fields.is_empty() {
        fields.push(field_description(
            EMPTY_STRUCT_MEMBER,
            primitive_type_id("uint8")?,
            0,
            0,
            "",
        ));
    }
    Some(format!(
        "{{\"type_name\": {}, \"fields\": [{}]}}",
        json_string(&ty.type_name()),
        fields.join(", ")
    ))
}

/// The JSON of one field `type_word name`.
fn field_json(
    owner: &MessageType,
    type_word: &str,
    name: &str,
    referenced: &mut Vec<(String, String)>,
) -> Option<String> {
    let (base, offset, capacity) = match type_word.split_once('[') {
        None => (type_word, 0, 0),
        Some((base, rest)) => {
            let inside = rest.strip_suffix(']')?;
            if inside.is_empty() {
                (base, FIELD_TYPE_UNBOUNDED_SEQUENCE_OFFSET, 0)
            } else if let Some(bound) = inside.strip_prefix("<=") {
                (
                    base,
                    FIELD_TYPE_BOUNDED_SEQUENCE_OFFSET,
                    bound.parse().ok()?,
                )
            } else {
                (base, FIELD_TYPE_ARRAY_OFFSET, inside.parse().ok()?)
            }
        }
    };
    if let Some((string_kind, bound)) = base.split_once("<=") {
        let id = match string_kind {
            "string" => FIELD_TYPE_BOUNDED_STRING,
            "wstring" => FIELD_TYPE_BOUNDED_WSTRING,
            _ => return None,
        };
        return Some(field_description(
            name,
            offset + id,
            capacity,
            bound.parse().ok()?,
            "",
        ));
    }
    if let Some(id) = primitive_type_id(base) {
        return Some(field_description(name, offset + id, capacity, 0, ""));
    }
    let nested = resolve(owner, base)?;
    let nested_name = nested.type_name();
    if !referenced.iter().any(|(n, _)| *n == nested_name) {
        // Reserve the slot first so that a type referring back to this one stops.
        referenced.push((nested_name.clone(), String::new()));
        let json = describe(nested, referenced)?;
        let slot = referenced.iter_mut().find(|(n, _)| *n == nested_name)?;
        slot.1 = json;
    }
    Some(field_description(
        name,
        offset + FIELD_TYPE_NESTED,
        capacity,
        0,
        &nested_name,
    ))
}

/// The dependency of `owner` that a field type `pkg/Name` (or `Name` of its own package) means.
fn resolve<'a>(owner: &'a MessageType, base: &str) -> Option<&'a MessageType> {
    let (package, name) = match base.split_once('/') {
        Some((package, name)) => (package, name.rsplit('/').next()?),
        None => (owner.package, base),
    };
    owner
        .dependencies
        .iter()
        .copied()
        .find(|d| d.package == package && d.name == name)
}

fn field_description(
    name: &str,
    type_id: u8,
    capacity: u64,
    string_capacity: u64,
    nested_type_name: &str,
) -> String {
    format!(
        "{{\"name\": {}, \"type\": {{\"type_id\": {type_id}, \"capacity\": {capacity}, \
         \"string_capacity\": {string_capacity}, \"nested_type_name\": {}}}}}",
        json_string(name),
        json_string(nested_type_name)
    )
}

fn json_string(s: &str) -> String {
    serde_json::to_string(s).expect("strings always serialise")
}

/// SHA-256 of `data` as lower-case hex.
fn sha256_hex(data: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(data)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

//! The JSON schema (draft 2020-12) embedded for each channel, derived from the channel's record
//! type (`schemars`, which follows the types' `serde` attributes), so the schema and the records
//! cannot drift apart. Doc comments become descriptions.
//!
//! Foxglove (and Lichtblick, its open fork) turns a channel's JSON schema into the fields its
//! panels plot and its 3D panel reads, and refuses the whole channel when the schema holds what
//! its reader does not know (`packages/mcap-support/src/parseJsonSchema.ts`): every property must
//! have one `type` (object, array, string, number, integer or boolean; no `null`, no list of
//! types), an array's items a type too, and a `oneOf` only numeric constants. So every schema
//! here is written in that subset, and is still a true JSON schema of the records:
//! - self-contained (no `$ref`), titled with the channel's schema name, an object at its root;
//! - an absent value is a property left out (records never hold `null`), not a nullable type;
//! - a string enum is `"enum"`, not a `oneOf` of constants (each value's doc goes to the
//!   description);
//! - a tagged union is one object: the tag an enum of the variants' names, every variant's
//!   fields as optional properties, each required field of every variant required.

use schemars::JsonSchema;
use schemars::generate::SchemaSettings;
use serde_json::{Value, json};

use super::foxglove::{AreaScene, Log, RouteScene, RtkPose, UwbPose};
use super::proto;
use super::records::{
    CarStateRecord, CommandAck, CommandSent, FaultRecord, OracleRecord, PlannedReturnRoute,
    PlannedSegment, SafetyRecord, SimEvent, SimFault, SimRange, TestEvent, TruthRecord,
};
use super::topic::Topic;

/// A channel's schema as a recording declares it.
#[derive(Debug, Clone)]
pub struct ChannelSchema {
    /// The schema encoding (`jsonschema`, `protobuf`).
    pub encoding: &'static str,
    /// The schema: a JSON schema's text, or a protobuf `FileDescriptorSet`.
    pub data: Vec<u8>,
}

/// The schema of `topic`'s channel in this build's encoding ([`Topic::encoding`]): the JSON
/// schema below, or the protobuf message's `FileDescriptorSet`.
pub fn channel_schema(topic: Topic) -> ChannelSchema {
    use ::foxglove::Encode;
    let protobuf = |data: Vec<u8>| ChannelSchema {
        encoding: "protobuf",
        data,
    };
    match topic {
        Topic::CarState => protobuf(proto::descriptor_set(
            topic.schema_name(),
            proto::CAR_STATE_FIELDS,
        )),
        Topic::SimTruth => protobuf(proto::descriptor_set(
            topic.schema_name(),
            proto::TRUTH_FIELDS,
        )),
        Topic::SimRanges => protobuf(proto::descriptor_set(
            topic.schema_name(),
            proto::SIM_RANGE_FIELDS,
        )),
        Topic::FoxgloveRtk | Topic::FoxgloveUwb => protobuf(
            ::foxglove::messages::PoseInFrame::get_schema()
                .map(|s| s.data.into_owned())
                .unwrap_or_default(),
        ),
        _ => ChannelSchema {
            encoding: "jsonschema",
            data: schema(topic).to_string().into_bytes(),
        },
    }
}

/// The JSON schema of `topic`'s records (the channel's schema in recordings of version 1 and 2,
/// and from version 3 on for every channel [`Topic::encoding`] names JSON).
pub fn schema(topic: Topic) -> Value {
    let mut root = match topic {
        Topic::CarState => derived::<CarStateRecord>(),
        Topic::Commands => derived::<CommandSent>(),
        Topic::Acks => derived::<CommandAck>(),
        Topic::Tests => derived::<TestEvent>(),
        Topic::PlanSegments => derived::<PlannedSegment>(),
        Topic::PlanReturnRoute => derived::<PlannedReturnRoute>(),
        Topic::Faults => derived::<FaultRecord>(),
        Topic::OracleSegments => derived::<OracleRecord>(),
        Topic::SafetyEvents => derived::<SafetyRecord>(),
        Topic::SimTruth => derived::<TruthRecord>(),
        Topic::SimRanges => derived::<SimRange>(),
        Topic::SimFaults => derived::<SimFault>(),
        Topic::SimEvents => derived::<SimEvent>(),
        Topic::FoxgloveArea => derived::<AreaScene>(),
        Topic::FoxgloveRoute => derived::<RouteScene>(),
        Topic::FoxgloveRtk => derived::<RtkPose>(),
        Topic::FoxgloveUwb => derived::<UwbPose>(),
        Topic::FoxgloveLog => derived::<Log>(),
    };
    plain(&mut root);
    if let Value::Object(map) = &mut root {
        map.insert("title".to_owned(), json!(topic.schema_name()));
    }
    root
}

/// `R`'s schema, every subschema inlined.
fn derived<R: JsonSchema>() -> Value {
    let mut settings = SchemaSettings::draft2020_12();
    settings.inline_subschemas = true;
    settings
        .into_generator()
        .into_root_schema_for::<R>()
        .to_value()
}

/// Rewrites `schema` (and every schema in it) into the subset Foxglove reads (see the module
/// doc): an `Option<T>` as `T` (records leave out what is absent), string enums as `enum`,
/// tagged unions as one object.
fn plain(schema: &mut Value) {
    let Value::Object(map) = schema else { return };
    if map.get("default").is_some_and(Value::is_null) {
        map.remove("default");
    }
    if let Some(Value::Array(types)) = map.get_mut("type") {
        types.retain(|t| t != "null");
        if let [only] = types.as_slice() {
            let only = only.clone();
            map.insert("type".to_owned(), only);
        }
    }
    if let Some(Value::Array(options)) = map.get("anyOf") {
        let null = json!({"type": "null"});
        if let [a, b] = options.as_slice()
            && (*a == null || *b == null)
            && let Value::Object(value) = if *a == null { b.clone() } else { a.clone() }
        {
            map.remove("anyOf");
            for (key, v) in value {
                map.entry(key).or_insert(v);
            }
        }
    }
    if let Some(Value::Array(mut variants)) = map.remove("oneOf") {
        variants.iter_mut().for_each(plain);
        if let Some(values) = string_constants(&variants) {
            map.insert("type".to_owned(), json!("string"));
            map.insert("enum".to_owned(), json!(values));
            append_description(map, &described(&variants, "const"));
        } else {
            merge_variants(map, variants);
        }
    }
    if let Some(Value::Object(properties)) = map.get_mut("properties") {
        properties.values_mut().for_each(plain);
    }
    if let Some(items) = map.get_mut("items") {
        plain(items);
    }
}

/// The values of `variants` when each is a string constant.
fn string_constants(variants: &[Value]) -> Option<Vec<&str>> {
    variants
        .iter()
        .map(|v| v.get("const").and_then(Value::as_str))
        .collect()
}

/// `- name: description` per variant, its name at `key` (a constant, or a tag's constant).
fn described(variants: &[Value], key: &str) -> String {
    variants
        .iter()
        .filter_map(|v| {
            let name = match key {
                "const" => v.get("const"),
                tag => v.pointer(&format!("/properties/{tag}/const")),
            }?;
            let description = v.get("description").and_then(Value::as_str).unwrap_or("");
            Some(format!(
                "- {}: {}",
                name.as_str()?,
                description.replace('\n', " ")
            ))
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn append_description(map: &mut serde_json::Map<String, Value>, more: &str) {
    let text = match map.get("description").and_then(Value::as_str) {
        Some(first) => format!("{first}\n{more}"),
        None => more.to_owned(),
    };
    map.insert("description".to_owned(), json!(text));
}

/// Makes `map` the object that is any of `variants` (objects of a tagged union): their
/// properties together, the tag (the property every variant holds as a constant) an enum of
/// their names, required what every variant requires.
fn merge_variants(map: &mut serde_json::Map<String, Value>, variants: Vec<Value>) {
    let mut properties = serde_json::Map::new();
    let mut tags: Vec<(String, Vec<Value>)> = Vec::new();
    let mut required: Option<Vec<Value>> = None;
    let mut closed = true;
    for variant in &variants {
        let own = variant.get("properties").and_then(Value::as_object);
        for (key, property) in own.into_iter().flatten() {
            if let Some(name) = property.get("const") {
                match tags.iter_mut().find(|(tag, _)| tag == key) {
                    Some((_, names)) => names.push(name.clone()),
                    None => tags.push((key.clone(), vec![name.clone()])),
                }
                continue;
            }
            let earlier = properties.entry(key.clone()).or_insert(property.clone());
            debug_assert!(
                same_shape(earlier, property),
                "variants disagree on {key}: {earlier} and {property}"
            );
        }
        let own_required = variant.get("required").and_then(Value::as_array);
        let own_required = own_required.cloned().unwrap_or_default();
        required = Some(match required {
            None => own_required,
            Some(all) => all
                .into_iter()
                .filter(|k| own_required.contains(k))
                .collect(),
        });
        closed &= variant.get("additionalProperties") == Some(&Value::Bool(false));
    }
    for (tag, names) in tags {
        let mut property = serde_json::Map::new();
        property.insert("type".to_owned(), json!("string"));
        property.insert("enum".to_owned(), json!(names));
        append_description(&mut property, &described(&variants, &tag));
        properties.insert(tag, Value::Object(property));
    }
    map.insert("type".to_owned(), json!("object"));
    map.insert("properties".to_owned(), Value::Object(properties));
    map.insert("required".to_owned(), json!(required.unwrap_or_default()));
    if closed {
        map.insert("additionalProperties".to_owned(), json!(false));
    }
}

/// Whether two schemas describe the same values (their descriptions aside).
fn same_shape(a: &Value, b: &Value) -> bool {
    fn strip(v: &Value) -> Value {
        match v {
            Value::Object(m) => Value::Object(
                m.iter()
                    .filter(|(k, _)| k.as_str() != "description")
                    .map(|(k, v)| (k.clone(), strip(v)))
                    .collect(),
            ),
            other => other.clone(),
        }
    }
    strip(a) == strip(b)
}

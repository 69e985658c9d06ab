//! The JSON schema (draft 2020-12) embedded for each channel: the shape of its records, written
//! by hand next to the types in `records.rs` (a test checks every record against its schema).
//!
//! A field the record may write as `null` (an absent value, or a number that was not finite)
//! allows `null`; a tagged union is an object with a `oneOf` of its variants.

use serde_json::{Value, json};

use super::topic::Topic;

/// The schema of `topic`'s records.
pub fn schema(topic: Topic) -> Value {
    let mut root = body(topic);
    if let Value::Object(map) = &mut root {
        map.insert(
            "$schema".to_owned(),
            json!("https://json-schema.org/draft/2020-12/schema"),
        );
        map.insert("title".to_owned(), json!(topic.schema_name()));
    }
    root
}

fn body(topic: Topic) -> Value {
    match topic {
        Topic::CarState => car_state(),
        Topic::Commands => command_sent(),
        Topic::Acks => command_ack(),
        Topic::Tests => test_event(),
        Topic::PlanSegments => planned_segment(),
        Topic::PlanReturnRoute => object(
            json!({"test_index": integer(), "points": array(route_point())}),
            &["test_index", "points"],
        ),
        Topic::Faults => fault(),
        Topic::OracleSegments => oracle(),
        Topic::SafetyEvents => safety(),
        Topic::SimTruth => truth(),
        Topic::SimRanges => sim_range(),
        Topic::SimFaults => sim_fault(),
        Topic::SimEvents => object(
            json!({"sim_ms": integer(), "event": strings(&[
                "watchdog_expired", "anchor_walk_would_hang", "zero_length_segment",
                "route_ring_overflow", "duplicate_packet_dropped",
            ])}),
            &["sim_ms", "event"],
        ),
        Topic::FoxgloveArea
        | Topic::FoxgloveRoute
        | Topic::FoxgloveRtk
        | Topic::FoxgloveUwb
        | Topic::FoxgloveLog => super::foxglove::schema(topic).unwrap_or_default(),
    }
}

fn object(properties: Value, required: &[&str]) -> Value {
    json!({"type": "object", "properties": properties, "required": required})
}

/// A tagged union: an object that is exactly one of `variants`.
fn union(variants: Vec<Value>) -> Value {
    json!({"type": "object", "oneOf": variants})
}

/// A variant of a tagged union: `tag` is `name`, plus `properties`.
fn variant(tag: &str, name: &str, properties: Value, required: &[&str]) -> Value {
    let mut object = object(properties, required);
    object["properties"][tag] = json!({"const": name});
    if let Some(list) = object["required"].as_array_mut() {
        list.insert(0, json!(tag));
    }
    object
}

fn number() -> Value {
    json!({"type": "number"})
}

/// A number written as `null` when absent or not finite.
fn number_or_null() -> Value {
    json!({"type": ["number", "null"]})
}

fn integer() -> Value {
    json!({"type": "integer"})
}

fn integer_or_null() -> Value {
    json!({"type": ["integer", "null"]})
}

fn string() -> Value {
    json!({"type": "string"})
}

fn boolean() -> Value {
    json!({"type": "boolean"})
}

fn strings(values: &[&str]) -> Value {
    json!({"type": "string", "enum": values})
}

fn array(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

fn position() -> Value {
    object(
        json!({"x": number_or_null(), "y": number_or_null()}),
        &["x", "y"],
    )
}

fn pose() -> Value {
    object(
        json!({"x": number_or_null(), "y": number_or_null(), "yaw_deg": number_or_null()}),
        &["x", "y", "yaw_deg"],
    )
}

fn route_point() -> Value {
    object(
        json!({"x": number(), "y": number(), "speed": number()}),
        &["x", "y", "speed"],
    )
}

fn point() -> Value {
    object(json!({"x": number(), "y": number()}), &["x", "y"])
}

fn car_state() -> Value {
    object(
        json!({
            "car_id": integer(),
            "requested_at_ns": integer(),
            "received_at_ns": integer(),
            "ms_today": integer(),
            "rtk": pose(),
            "uwb": position(),
            "gnss": position(),
            "deviation_m": number_or_null(),
            "speed_mps": number_or_null(),
            "route_left": integer(),
            "goal": position(),
            "look_ahead_radius_m": number_or_null(),
            "input_voltage_v": number_or_null(),
            "mc_fault": integer(),
        }),
        &[
            "car_id",
            "requested_at_ns",
            "received_at_ns",
            "ms_today",
            "rtk",
            "uwb",
            "gnss",
            "speed_mps",
            "route_left",
            "goal",
            "look_ahead_radius_m",
            "input_voltage_v",
            "mc_fault",
        ],
    )
}

fn car_command() -> Value {
    let tagged =
        |name, properties, required: &[&str]| variant("command", name, properties, required);
    let points = || json!({"points": array(route_point())});
    union(vec![
        tagged("add_points", points(), &["points"]),
        tagged("replace_route", points(), &["points"]),
        tagged("clear_route", json!({}), &[]),
        tagged("remove_last_point", json!({}), &[]),
        tagged(
            "set_autopilot",
            json!({"active": boolean(), "reset": boolean()}),
            &["active", "reset"],
        ),
        tagged("brake", json!({"current_a": number()}), &["current_a"]),
        tagged("set_pos", json!({"pose": pose()}), &["pose"]),
        tagged("clear_faults", json!({}), &[]),
        tagged(
            "set_fault_injection",
            json!({"enabled": boolean()}),
            &["enabled"],
        ),
        tagged("reset_uwb_pos", json!({}), &[]),
        tagged("terminal", json!({"text": string()}), &["text"]),
    ])
}

fn command_sent() -> Value {
    object(
        json!({"id": integer(), "test_index": integer_or_null(), "command": car_command()}),
        &["id", "command"],
    )
}

fn command_ack() -> Value {
    let outcome = union(vec![
        variant("status", "acked", json!({}), &[]),
        variant("status", "failed", json!({"error": string()}), &["error"]),
    ]);
    object(
        json!({
            "id": integer(),
            "command": string(),
            "outcome": outcome,
            "round_trip_ms": number_or_null(),
        }),
        &["id", "command", "outcome"],
    )
}

fn test_event() -> Value {
    let event = union(vec![
        variant(
            "event",
            "started",
            json!({"commands": integer()}),
            &["commands"],
        ),
        variant(
            "event",
            "ended",
            json!({
                "verdict": strings(&["passed", "failed", "aborted"]),
                "reason": {"type": ["string", "null"]},
            }),
            &["verdict"],
        ),
    ]);
    object(
        json!({"test_index": integer(), "event": event}),
        &["test_index", "event"],
    )
}

fn planned_segment() -> Value {
    let intent = object(
        json!({"seed": integer(), "points": integer(), "speed_mps": number()}),
        &["seed", "points", "speed_mps"],
    );
    object(
        json!({
            "test_index": integer(),
            "command_index": integer(),
            "segment_index": integer(),
            "intent": intent,
            "points": array(route_point()),
            "margin": array(point()),
        }),
        &[
            "test_index",
            "command_index",
            "segment_index",
            "points",
            "margin",
        ],
    )
}

fn fault() -> Value {
    let spec = object(
        json!({
            "probe": string(),
            "kind": strings(&["bitflip", "offset", "amplification", "set_to", "none"]),
            "param": number(),
            "start": integer(),
            "duration": integer(),
        }),
        &["probe", "kind", "param", "start", "duration"],
    );
    let status = union(vec![
        variant("status", "sent", json!({}), &[]),
        variant("status", "confirmed", json!({}), &[]),
        variant("status", "refused", json!({"error": string()}), &["error"]),
        variant(
            "status",
            "placed",
            json!({"placement": placement()}),
            &["placement"],
        ),
    ]);
    object(
        json!({
            "test_index": integer(),
            "command_index": integer(),
            "fault": spec,
            "status": status,
        }),
        &["test_index", "command_index", "fault", "status"],
    )
}

/// A fault's placement: `campaign::drive::FaultPlacement`.
fn placement() -> Value {
    object(
        json!({
            "command_index": integer(),
            "rule": strings(&["planned", "earlier_tool"]),
            "segment_index": integer(),
            "planned_along_m": number(),
            "sent_s": number(),
            "added_s": number(),
            "actual_along_m": number(),
            "error_m": number(),
            "acts_from_s": number(),
            "acts_to_s": number(),
        }),
        &[
            "command_index",
            "rule",
            "segment_index",
            "planned_along_m",
            "sent_s",
            "added_s",
            "acts_from_s",
            "acts_to_s",
        ],
    )
}

fn oracle() -> Value {
    let stats = json!({
        "type": ["object", "null"],
        "properties": {
            "samples": integer(),
            "max_m": number(),
            "rms_m": number(),
            "p95_m": number(),
        },
        "required": ["samples", "max_m", "rms_m", "p95_m"],
    });
    let outcome = object(
        json!({
            "stats": stats,
            "invalid_uwb_samples": integer(),
            "unjudged_samples": integer(),
            "threshold_m": number(),
            "verdict": strings(&["passed", "failed", "no_samples"]),
        }),
        &[
            "stats",
            "invalid_uwb_samples",
            "unjudged_samples",
            "threshold_m",
            "verdict",
        ],
    );
    let result = object(
        json!({
            "segment_index": integer(),
            "command_index": integer(),
            "faults_preceding": array(integer()),
            "faults_active": array(integer()),
            "oracle": outcome,
        }),
        &[
            "segment_index",
            "command_index",
            "faults_preceding",
            "oracle",
        ],
    );
    object(
        json!({"test_index": integer(), "result": result}),
        &["test_index", "result"],
    )
}

fn safety() -> Value {
    let reason = object(
        json!({
            "kind": strings(&[
                "outside_fence", "inside_cutout", "off_route", "stale_telemetry",
                "no_position", "rtk_lost", "link_lost", "starved", "interrupted",
            ]),
            "x": number(),
            "y": number(),
            "distance_m": number(),
            "cross_track_m": number(),
            "age_ms": integer(),
        }),
        &["kind"],
    );
    let abort = object(
        json!({
            "reason": reason,
            "action": strings(&["safe_stop", "brake"]),
            "at": integer(),
        }),
        &["reason", "action", "at"],
    );
    object(
        json!({"test_index": integer_or_null(), "abort": abort, "message": string()}),
        &["abort", "message"],
    )
}

fn truth() -> Value {
    object(
        json!({
            "sim_ms": integer(),
            "position": position(),
            "heading_rad": number_or_null(),
            "speed_mps": number_or_null(),
            "steering_rad": number_or_null(),
            "fused": pose(),
            "uwb": pose(),
            "fused_error_m": number_or_null(),
            "uwb_error_m": number_or_null(),
        }),
        &[
            "sim_ms",
            "position",
            "heading_rad",
            "speed_mps",
            "steering_rad",
            "fused",
            "uwb",
        ],
    )
}

fn sim_range() -> Value {
    let path = json!({
        "type": ["object", "null"],
        "properties": {
            "kind": strings(&["line_of_sight", "reflected", "blocked"]),
            "length_m": number_or_null(),
            "wall": integer_or_null(),
            "direct_m": number_or_null(),
        },
        "required": ["kind"],
    });
    union(vec![
        variant(
            "event",
            "request",
            json!({
                "sim_ms": integer(),
                "anchor": integer(),
                "path": path,
                "true_range_m": number_or_null(),
                "outcome": strings(&["measured", "blocked", "dropped", "no_responder"]),
                "range_m": number_or_null(),
            }),
            &["sim_ms", "anchor", "outcome"],
        ),
        variant(
            "event",
            "fused",
            json!({
                "sim_ms": integer(),
                "anchor": integer(),
                "range_m": number_or_null(),
                "moved": boolean(),
            }),
            &["sim_ms", "anchor", "range_m", "moved"],
        ),
    ])
}

fn sim_fault() -> Value {
    object(
        json!({
            "sim_ms": integer(),
            "probe": string(),
            "slots": integer(),
            "iteration": integer(),
            "before": number_or_null(),
            "after": number_or_null(),
        }),
        &["sim_ms", "probe", "slots", "iteration", "before", "after"],
    )
}

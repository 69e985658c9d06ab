//! The high-rate channels in protobuf (recording version 3): `/car/state` as
//! `drivecheck.CarState`, `/sim/truth` as `drivecheck.SimTruth` and (from version 4)
//! `/sim/ranges` as `drivecheck.SimRange` here, `/foxglove/rtk` and
//! `/foxglove/uwb` as Foxglove's own `foxglove.PoseInFrame` (`super::foxglove`).
//!
//! Nothing is written twice: the RTK and UWB positions of a state sample are on the pose
//! channels, and `drivecheck.CarState` holds them only where a pose cannot (a position that is
//! not finite has no pose). The RTK yaw is in `drivecheck.CarState` as the car sent it (the RTK
//! pose's quaternion draws it, but would not give the number back exactly). The reader joins
//! them again ([`super::Recording::messages`]). What is derived
//! (|UWB − RTK|, the estimates' distances from the truth) is computed again when read; the
//! state's `deviation_m` is kept as a `float` only so that Foxglove can plot it.
//!
//! Every value is stored as it was held: `double` for the `f64`s, `float` for what the
//! simulated firmware holds as `f32`. The schemas are `FileDescriptorSet`s built from
//! [`CAR_STATE_FIELDS`] and [`TRUTH_FIELDS`]; a test checks them against the messages' encoding.

use prost::Message;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};

/// `/car/state` in protobuf (see the module doc for what it leaves to the pose channels).
#[derive(Clone, PartialEq, Message)]
pub(super) struct CarStatePb {
    #[prost(uint32, tag = "1")]
    pub car_id: u32,
    #[prost(uint64, tag = "2")]
    pub requested_at_ns: u64,
    #[prost(uint64, tag = "3")]
    pub received_at_ns: u64,
    #[prost(sint32, tag = "4")]
    pub ms_today: i32,
    #[prost(float, tag = "5")]
    pub deviation_m: f32,
    #[prost(double, tag = "6")]
    pub gnss_x: f64,
    #[prost(double, tag = "7")]
    pub gnss_y: f64,
    #[prost(double, tag = "8")]
    pub speed_mps: f64,
    #[prost(sint32, tag = "9")]
    pub route_left: i32,
    #[prost(double, tag = "10")]
    pub goal_x: f64,
    #[prost(double, tag = "11")]
    pub goal_y: f64,
    #[prost(double, tag = "12")]
    pub look_ahead_radius_m: f64,
    #[prost(double, tag = "13")]
    pub input_voltage_v: f64,
    #[prost(uint32, tag = "14")]
    pub mc_fault: u32,
    #[prost(double, optional, tag = "15")]
    pub rtk_x: Option<f64>,
    #[prost(double, optional, tag = "16")]
    pub rtk_y: Option<f64>,
    #[prost(double, tag = "17")]
    pub rtk_yaw_deg: f64,
    #[prost(double, optional, tag = "18")]
    pub uwb_x: Option<f64>,
    #[prost(double, optional, tag = "19")]
    pub uwb_y: Option<f64>,
}

/// The fields of `drivecheck.CarState`, as its schema declares them.
pub(super) const CAR_STATE_FIELDS: &[(&str, i32, Type)] = &[
    ("car_id", 1, Type::Uint32),
    ("requested_at_ns", 2, Type::Uint64),
    ("received_at_ns", 3, Type::Uint64),
    ("ms_today", 4, Type::Sint32),
    ("deviation_m", 5, Type::Float),
    ("gnss_x", 6, Type::Double),
    ("gnss_y", 7, Type::Double),
    ("speed_mps", 8, Type::Double),
    ("route_left", 9, Type::Sint32),
    ("goal_x", 10, Type::Double),
    ("goal_y", 11, Type::Double),
    ("look_ahead_radius_m", 12, Type::Double),
    ("input_voltage_v", 13, Type::Double),
    ("mc_fault", 14, Type::Uint32),
    ("rtk_x", 15, Type::Double),
    ("rtk_y", 16, Type::Double),
    ("rtk_yaw_deg", 17, Type::Double),
    ("uwb_x", 18, Type::Double),
    ("uwb_y", 19, Type::Double),
];

/// `/sim/truth` in protobuf: the truth in `double`, the firmware's estimates in `float` (as the
/// simulated firmware holds them); the estimates' errors are computed again when read.
#[derive(Clone, PartialEq, Message)]
pub(super) struct TruthPb {
    #[prost(uint64, tag = "1")]
    pub sim_ms: u64,
    #[prost(double, tag = "2")]
    pub x: f64,
    #[prost(double, tag = "3")]
    pub y: f64,
    #[prost(double, tag = "4")]
    pub heading_rad: f64,
    #[prost(double, tag = "5")]
    pub speed_mps: f64,
    #[prost(double, tag = "6")]
    pub steering_rad: f64,
    #[prost(float, tag = "7")]
    pub fused_x: f32,
    #[prost(float, tag = "8")]
    pub fused_y: f32,
    #[prost(float, tag = "9")]
    pub fused_yaw_deg: f32,
    #[prost(float, tag = "10")]
    pub uwb_x: f32,
    #[prost(float, tag = "11")]
    pub uwb_y: f32,
    #[prost(float, tag = "12")]
    pub uwb_yaw_deg: f32,
}

/// The fields of `drivecheck.SimTruth`, as its schema declares them.
pub(super) const TRUTH_FIELDS: &[(&str, i32, Type)] = &[
    ("sim_ms", 1, Type::Uint64),
    ("x", 2, Type::Double),
    ("y", 3, Type::Double),
    ("heading_rad", 4, Type::Double),
    ("speed_mps", 5, Type::Double),
    ("steering_rad", 6, Type::Double),
    ("fused_x", 7, Type::Float),
    ("fused_y", 8, Type::Float),
    ("fused_yaw_deg", 9, Type::Float),
    ("uwb_x", 10, Type::Float),
    ("uwb_y", 11, Type::Float),
    ("uwb_yaw_deg", 12, Type::Float),
];

/// `/sim/ranges` in protobuf (from recording version 4): one flat message for both events (a
/// range request and its fate, or a range reaching the estimator), each value as the simulator
/// holds it (`float` for the firmware's `f32` ranges); an absent optional field is a value the
/// event does not have.
#[derive(Clone, PartialEq, Message)]
pub(super) struct SimRangePb {
    /// 0 a range request, 1 a range reaching the estimator.
    #[prost(uint32, tag = "1")]
    pub event: u32,
    #[prost(uint64, tag = "2")]
    pub sim_ms: u64,
    #[prost(uint32, tag = "3")]
    pub anchor: u32,
    /// 0 line of sight, 1 reflected, 2 blocked (a request whose anchor answers).
    #[prost(uint32, optional, tag = "4")]
    pub path_kind: Option<u32>,
    #[prost(double, optional, tag = "5")]
    pub path_length_m: Option<f64>,
    #[prost(uint64, optional, tag = "6")]
    pub path_wall: Option<u64>,
    #[prost(double, optional, tag = "7")]
    pub path_direct_m: Option<f64>,
    #[prost(double, optional, tag = "8")]
    pub true_range_m: Option<f64>,
    /// 0 measured, 1 blocked, 2 dropped, 3 no responder (a request).
    #[prost(uint32, tag = "9")]
    pub outcome: u32,
    #[prost(float, optional, tag = "10")]
    pub range_m: Option<f32>,
    #[prost(bool, tag = "11")]
    pub moved: bool,
}

/// The fields of `drivecheck.SimRange`, as its schema declares them.
pub(super) const SIM_RANGE_FIELDS: &[(&str, i32, Type)] = &[
    ("event", 1, Type::Uint32),
    ("sim_ms", 2, Type::Uint64),
    ("anchor", 3, Type::Uint32),
    ("path_kind", 4, Type::Uint32),
    ("path_length_m", 5, Type::Double),
    ("path_wall", 6, Type::Uint64),
    ("path_direct_m", 7, Type::Double),
    ("true_range_m", 8, Type::Double),
    ("outcome", 9, Type::Uint32),
    ("range_m", 10, Type::Float),
    ("moved", 11, Type::Bool),
];

/// The `FileDescriptorSet` of message `full_name` (`drivecheck.CarState`) with `fields`, every
/// one optional (proto2: an absent field reads as its default, as the message types above
/// encode it).
pub(super) fn descriptor_set(full_name: &str, fields: &[(&str, i32, Type)]) -> Vec<u8> {
    let (package, name) = full_name.rsplit_once('.').unwrap_or(("", full_name));
    let message = DescriptorProto {
        name: Some(name.to_owned()),
        field: fields
            .iter()
            .map(|&(field, number, kind)| FieldDescriptorProto {
                name: Some(field.to_owned()),
                number: Some(number),
                label: Some(Label::Optional as i32),
                r#type: Some(kind as i32),
                json_name: Some(field.to_owned()),
                ..FieldDescriptorProto::default()
            })
            .collect(),
        ..DescriptorProto::default()
    };
    let file = FileDescriptorProto {
        name: Some(format!("{}.proto", full_name.replace('.', "/"))),
        package: Some(package.to_owned()),
        message_type: vec![message],
        syntax: Some("proto2".to_owned()),
        ..FileDescriptorProto::default()
    };
    FileDescriptorSet { file: vec![file] }.encode_to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The field numbers and wire types a message's bytes hold.
    fn wire_fields(mut bytes: &[u8]) -> Vec<(u32, u8)> {
        let mut fields = Vec::new();
        while !bytes.is_empty() {
            let key = prost::encoding::decode_varint(&mut bytes).expect("key");
            let wire = (key & 7) as u8;
            fields.push(((key >> 3) as u32, wire));
            let skip = match wire {
                0 => {
                    prost::encoding::decode_varint(&mut bytes).expect("varint");
                    0
                }
                1 => 8,
                5 => 4,
                2 => prost::encoding::decode_varint(&mut bytes).expect("length") as usize,
                other => panic!("wire type {other}"),
            };
            bytes = &bytes[skip..];
        }
        fields
    }

    fn wire_type(kind: Type) -> u8 {
        match kind {
            Type::Double => 1,
            Type::Float => 5,
            _ => 0,
        }
    }

    /// Every field of a message with every value set is declared with its number and wire type,
    /// and every declared field is written.
    fn check(bytes: &[u8], fields: &[(&str, i32, Type)]) {
        let written = wire_fields(bytes);
        let declared: Vec<(u32, u8)> = fields
            .iter()
            .map(|&(_, number, kind)| (number as u32, wire_type(kind)))
            .collect();
        assert_eq!(written, declared);
    }

    #[test]
    fn the_schemas_declare_what_the_messages_write() {
        let state = CarStatePb {
            car_id: 1,
            requested_at_ns: 2,
            received_at_ns: 3,
            ms_today: -1,
            deviation_m: 0.5,
            gnss_x: 1.0,
            gnss_y: 2.0,
            speed_mps: 3.0,
            route_left: 4,
            goal_x: 5.0,
            goal_y: 6.0,
            look_ahead_radius_m: -1.0,
            input_voltage_v: 39.0,
            mc_fault: 7,
            rtk_x: Some(f64::NAN),
            rtk_y: Some(1.0),
            rtk_yaw_deg: 2.0,
            uwb_x: Some(3.0),
            uwb_y: Some(f64::INFINITY),
        };
        check(&state.encode_to_vec(), CAR_STATE_FIELDS);
        let truth = TruthPb {
            sim_ms: 1,
            x: 1.0,
            y: 2.0,
            heading_rad: 3.0,
            speed_mps: 4.0,
            steering_rad: 5.0,
            fused_x: 6.0,
            fused_y: 7.0,
            fused_yaw_deg: 8.0,
            uwb_x: 9.0,
            uwb_y: 10.0,
            uwb_yaw_deg: 11.0,
        };
        check(&truth.encode_to_vec(), TRUTH_FIELDS);
        let range = SimRangePb {
            event: 1,
            sim_ms: 2,
            anchor: 3,
            path_kind: Some(1),
            path_length_m: Some(4.0),
            path_wall: Some(5),
            path_direct_m: Some(6.0),
            true_range_m: Some(7.0),
            outcome: 2,
            range_m: Some(8.0),
            moved: true,
        };
        check(&range.encode_to_vec(), SIM_RANGE_FIELDS);
    }
}

//! `drivecheck calibrate` end to end: it fits a profile from what a car reports, and only from
//! that — the same profile when every `/sim/*` channel, the recorded profile and the case files'
//! `car_profile` are removed from the run directory.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{campaign, drivecheck, path, text};

use car_sim::CarProfile;

const CAR: &str = r#"
format = "drivecheck-car-profile"
version = 1
[anchors."50"]
offset_m = [0.35, -0.2]
range_bias_m = 0.12
[anchors."234"]
offset_m = [-0.25, 0.3]
range_bias_m = -0.08
"#;

/// A copy of `mcap` without the `/sim/*` channels and the simulator's profile record, every other
/// record in its order.
fn strip_recording(from: &Path, to: &Path) {
    let bytes = std::fs::read(from).unwrap();
    let file = std::io::BufWriter::new(std::fs::File::create(to).unwrap());
    let mut writer = mcap::Writer::new(file).unwrap();
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    for record in mcap::read::ChunkFlattener::new(&bytes).unwrap() {
        match record.unwrap() {
            mcap::records::Record::Schema { header, data } => {
                let id = writer
                    .add_schema(&header.name, &header.encoding, &data)
                    .unwrap();
                schemas.insert(header.id, id);
            }
            mcap::records::Record::Channel(c) if !c.topic.starts_with("/sim/") => {
                let id = writer
                    .add_channel(
                        schemas[&c.schema_id],
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )
                    .unwrap();
                channels.insert(c.id, id);
            }
            mcap::records::Record::Message { header, data } => {
                if let Some(&id) = channels.get(&header.channel_id) {
                    let header = mcap::records::MessageHeader {
                        channel_id: id,
                        ..header
                    };
                    writer.write_to_known_channel(&header, &data).unwrap();
                }
            }
            mcap::records::Record::Metadata(m) if m.name != "drivecheck.sim.profile" => {
                writer.write_metadata(&m).unwrap();
            }
            _ => {}
        }
    }
    writer.finish().unwrap();
}

/// A copy of the run directory `from` with nothing of the simulator's truth.
fn strip_run(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let file = entry.unwrap().path();
        let name = file.file_name().unwrap().to_str().unwrap().to_owned();
        if name == "campaign.mcap" {
            strip_recording(&file, &to.join(&name));
        } else if name.ends_with(".json") {
            let mut json: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
            json.as_object_mut().unwrap().remove("car_profile");
            std::fs::write(to.join(&name), serde_json::to_string_pretty(&json).unwrap()).unwrap();
        }
    }
}

fn calibrate(run: &Path, out: &Path) -> CarProfile {
    let result = drivecheck(&[
        "calibrate",
        path(run),
        "--out",
        path(out),
        "--max-evaluations",
        "12",
        // One start: what is checked is what the fit reads, not how good it gets.
        "--restarts",
        "0",
    ]);
    assert_eq!(result.status.code(), Some(0), "{}", text(&result));
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        stdout.contains("| anchors.\"50\".offset_m[0] |"),
        "{stdout}"
    );
    assert!(stdout.contains("fit: rms misfit"), "{stdout}");
    let written = std::fs::read_to_string(out).unwrap();
    assert!(
        written.starts_with("# Calibrated by drivecheck"),
        "{written}"
    );
    CarProfile::from_toml(&written, "fitted").unwrap()
}

#[test]
fn calibrate_fits_from_what_a_car_reports_only() {
    let tmp = tempfile::tempdir().unwrap();
    let car = tmp.path().join("car.toml");
    std::fs::write(&car, CAR).unwrap();
    let run = campaign(tmp.path(), 21, 3, &["--profile", path(&car)], 1);
    let stripped = tmp.path().join("stripped");
    strip_run(&run, &stripped);
    let recording = recording::Recording::read(&stripped.join("campaign.mcap")).unwrap();
    assert!(recording.channels().all(|c| !c.topic.starts_with("/sim/")));
    assert!(recording.metadata("drivecheck.sim.profile").is_none());
    assert!(recording.count(recording::Topic::CarState) > 100);

    let fitted = calibrate(&run, &tmp.path().join("a.toml"));
    let blind = calibrate(&stripped, &tmp.path().join("b.toml"));
    assert_eq!(fitted, blind, "calibrate never reads the simulator's truth");
    assert_ne!(fitted, CarProfile::default(), "the fit moved");
    assert!(fitted.anchors.contains_key(&50) && fitted.anchors.contains_key(&234));
}

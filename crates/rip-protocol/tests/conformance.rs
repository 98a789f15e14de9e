//! Runs the conformance vectors of `vectors.toml` (referenced by docs/protocol.md) against the
//! encoder, the CRC and the parser.

use rip_protocol::{
    crc16, crc32, crc32_update, encode, Ack, Command, Event, Frame, Measurement, Message,
    OnboardStart, Parser, PilMove, PilStep, Rejection, Telemetry, UploadBegin, UploadChunk,
    UploadCommit, WatchdogStop, MAX_FRAME,
};
use toml::Value;

fn vectors() -> toml::Table {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/vectors.toml");
    std::fs::read_to_string(path)
        .expect("vectors.toml")
        .parse()
        .expect("vectors.toml is TOML")
}

fn entries<'a>(t: &'a toml::Table, key: &str) -> &'a [Value] {
    t[key].as_array().expect(key)
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect()
}

fn int(v: &Value, key: &str) -> i64 {
    v.get(key)
        .and_then(Value::as_integer)
        .unwrap_or_else(|| panic!("missing integer `{key}` in {v}"))
}

fn name(v: &Value) -> &str {
    v["name"].as_str().expect("name")
}

fn frame_of(v: &Value) -> Frame {
    let message = match v["type"].as_str().expect("type") {
        "command" => Message::Command(Command {
            voltage_mv: int(v, "voltage_mv") as i16,
            flags: int(v, "flags") as u8,
        }),
        "sample_request" => Message::SampleRequest,
        "measurement" => Message::Measurement(Measurement {
            ack_seq: int(v, "ack_seq") as u16,
            arm_counts: int(v, "arm_counts") as i32,
            pendulum_counts: int(v, "pendulum_counts") as i32,
            applied_mv: int(v, "applied_mv") as i16,
            status: int(v, "status") as u8,
            device_time_us: int(v, "device_time_us") as u32,
        }),
        "upload_begin" => Message::UploadBegin(UploadBegin {
            total_len: int(v, "total_len") as u32,
        }),
        "upload_chunk" => Message::UploadChunk(UploadChunk::new(
            int(v, "offset") as u32,
            &hex(v["data"].as_str().expect("data")),
        )),
        "upload_commit" => Message::UploadCommit(UploadCommit {
            len: int(v, "len") as u32,
            crc32: int(v, "crc32") as u32,
        }),
        "onboard_start" => Message::OnboardStart(OnboardStart {
            decimation: int(v, "decimation") as u16,
            host_timeout_ms: int(v, "host_timeout_ms") as u16,
            arm_center: int(v, "arm_center") as i32,
            arm_limit: int(v, "arm_limit") as u32,
            pendulum_center: int(v, "pendulum_center") as i32,
            pendulum_limit: int(v, "pendulum_limit") as u32,
            flags: v.get("flags").map_or(0, |_| int(v, "flags") as u8),
        }),
        "onboard_stop" => Message::OnboardStop {
            flags: int(v, "flags") as u8,
        },
        "watchdog_stop" => Message::WatchdogStop(WatchdogStop {
            flags: int(v, "flags") as u8,
            arm_zero: int(v, "arm_zero") as i32,
            pendulum_down: int(v, "pendulum_down") as i32,
        }),
        "ack" => Message::Ack(Ack {
            ack_seq: int(v, "ack_seq") as u16,
            request: int(v, "request") as u8,
            code: int(v, "code") as u8,
            value: int(v, "value") as u32,
        }),
        "telemetry" => Message::Telemetry(Telemetry {
            step: int(v, "step") as u32,
            device_time_us: int(v, "device_time_us") as u32,
            arm_counts: int(v, "arm_counts") as i32,
            pendulum_counts: int(v, "pendulum_counts") as i32,
            applied_mv: int(v, "applied_mv") as i16,
            status: int(v, "status") as u8,
            onboard: int(v, "onboard") as u8,
            step_cycles: int(v, "step_cycles") as u32,
            overruns: int(v, "overruns") as u16,
            fallbacks: int(v, "fallbacks") as u16,
        }),
        "pil_step" => Message::PilStep(PilStep {
            arm_counts: int(v, "arm_counts") as i32,
            pendulum_counts: int(v, "pendulum_counts") as i32,
            flags: int(v, "flags") as u8,
        }),
        "pil_move" => Message::PilMove(PilMove {
            ack_seq: int(v, "ack_seq") as u16,
            step: int(v, "step") as u32,
            voltage_bits: v["voltage"].as_float().expect("voltage").to_bits(),
            cycles: int(v, "cycles") as u32,
            code: int(v, "code") as u8,
        }),
        other => panic!("unknown type {other}"),
    };
    Frame {
        seq: int(v, "seq") as u16,
        message,
    }
}

fn event_name(e: &Event) -> &'static str {
    match e {
        Event::Frame(_) => "frame",
        Event::Rejected(Rejection::Crc) => "crc",
        Event::Rejected(Rejection::BadHeader) => "bad_header",
        Event::Rejected(Rejection::Version(_)) => "version",
        Event::Rejected(Rejection::Unknown { .. }) => "unknown",
    }
}

/// Every event of `stream`, fed one byte at a time as a UART delivers it.
fn events(stream: &[u8]) -> (Vec<Event>, Parser) {
    let mut parser = Parser::new();
    let mut out = Vec::new();
    for &b in stream {
        parser.push(b);
        while let Some(e) = parser.poll_event() {
            out.push(e);
        }
    }
    (out, parser)
}

#[test]
fn crc_vectors() {
    let t = vectors();
    for v in entries(&t, "crc") {
        let data = match v.get("ascii") {
            Some(s) => s.as_str().unwrap().as_bytes().to_vec(),
            None => hex(v["hex"].as_str().unwrap()),
        };
        assert_eq!(crc16(&data), int(v, "crc") as u16, "{}", name(v));
    }
}

#[test]
fn crc32_vectors_also_chunk_by_chunk() {
    let t = vectors();
    let vs = entries(&t, "crc32");
    assert!(vs.len() >= 3);
    for v in vs {
        let data = match v.get("ascii") {
            Some(s) => s.as_str().unwrap().as_bytes().to_vec(),
            None => hex(v["hex"].as_str().unwrap()),
        };
        let want = int(v, "crc") as u32;
        assert_eq!(crc32(&data), want, "{}", name(v));
        // An image checked in upload-sized pieces gives the same value.
        let mut c = 0;
        for piece in data.chunks(5) {
            c = crc32_update(c, piece);
        }
        assert_eq!(c, want, "{} in pieces", name(v));
    }
}

#[test]
fn every_message_type_has_a_frame_vector() {
    let t = vectors();
    let types: std::collections::BTreeSet<&str> = entries(&t, "frame")
        .iter()
        .map(|v| v["type"].as_str().unwrap())
        .collect();
    for kind in [
        "command",
        "sample_request",
        "measurement",
        "upload_begin",
        "upload_chunk",
        "upload_commit",
        "onboard_start",
        "onboard_stop",
        "watchdog_stop",
        "ack",
        "telemetry",
        "pil_step",
        "pil_move",
    ] {
        assert!(types.contains(kind), "no frame vector of {kind}");
    }
}

#[test]
fn frame_vectors_encode_and_decode() {
    let t = vectors();
    let frames = entries(&t, "frame");
    assert!(frames.len() >= 5);
    for v in frames {
        let bytes = hex(v["hex"].as_str().unwrap());
        let frame = frame_of(v);
        let mut out = [0u8; MAX_FRAME];
        let n = encode(&frame, &mut out);
        assert_eq!(&out[..n], &bytes[..], "encoding {}", name(v));
        let (ev, parser) = events(&bytes);
        assert_eq!(ev, vec![Event::Frame(frame)], "decoding {}", name(v));
        assert_eq!(parser.stats().frames, 1);
        assert_eq!(parser.stats().errors(), 0);
    }
}

#[test]
fn stream_vectors_parse_as_specified() {
    let t = vectors();
    let streams = entries(&t, "stream");
    assert!(streams.len() >= 10);
    for v in streams {
        let bytes = hex(v["hex"].as_str().unwrap());
        let (ev, parser) = events(&bytes);
        let names: Vec<&str> = ev.iter().map(event_name).collect();
        let expected: Vec<&str> = v["events"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e.as_str().unwrap())
            .collect();
        assert_eq!(names, expected, "events of {}", name(v));
        let frames: Vec<Frame> = ev
            .iter()
            .filter_map(|e| match e {
                Event::Frame(f) => Some(*f),
                Event::Rejected(_) => None,
            })
            .collect();
        let expected: Vec<Frame> = v["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(frame_of)
            .collect();
        assert_eq!(frames, expected, "frames of {}", name(v));
        let s = parser.stats();
        assert_eq!(s.frames, frames.len() as u64, "{}", name(v));
        assert_eq!(s.errors(), (ev.len() - frames.len()) as u64, "{}", name(v));
        if let Some(skipped) = v.get("skipped_bytes") {
            assert_eq!(
                s.skipped_bytes,
                skipped.as_integer().unwrap() as u64,
                "skipped bytes of {}",
                name(v)
            );
        }
        // The same stream fed in one call decodes the same frames.
        let mut whole = Parser::new();
        let mut got = Vec::new();
        whole.feed(&bytes, |f| got.push(f));
        assert_eq!(got, frames, "{}", name(v));
    }
}

#[test]
fn the_version_rejection_reports_the_version() {
    let t = vectors();
    let v = entries(&t, "stream")
        .iter()
        .find(|v| name(v).contains("version 4 is rejected whole"))
        .expect("version vector");
    let (ev, parser) = events(&hex(v["hex"].as_str().unwrap()));
    assert_eq!(ev[0], Event::Rejected(Rejection::Version(4)));
    assert_eq!(parser.stats().version_mismatches, 1);
}

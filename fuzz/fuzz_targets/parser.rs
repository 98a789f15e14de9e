//! The protocol parser on arbitrary bytes mixed with valid frames: it never panics, counts
//! every event once, decodes only frames whose exact encoding occurs in the input, and decodes
//! the same frames whether the bytes arrive one at a time or in one call.
//!
//! Input layout: records of a tag byte; tag bit 7 set makes the record a valid frame built from
//! the next bytes (type from bits 0–1, sequence number, payload fields), so that the fuzzer
//! exercises decoding and resynchronisation around real frames without forging CRCs; otherwise
//! bits 0–6 give the length of a chunk of raw bytes that follows.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_protocol::{encode, Command, Event, Frame, Measurement, Message, Parser, MAX_FRAME};

fn take<const N: usize>(rest: &mut &[u8]) -> [u8; N] {
    let mut out = [0u8; N];
    let n = N.min(rest.len());
    out[..n].copy_from_slice(&rest[..n]);
    *rest = &rest[n..];
    out
}

fuzz_target!(|data: &[u8]| {
    // Build the stream.
    let mut stream = [0u8; 4096];
    let mut len = 0usize;
    let mut rest = data;
    while let Some((&tag, tail)) = rest.split_first() {
        rest = tail;
        let mut buf = [0u8; MAX_FRAME];
        let bytes: &[u8] = if tag & 0x80 != 0 {
            let seq = u16::from_le_bytes(take::<2>(&mut rest));
            let message = match tag & 3 {
                0 => Message::SampleRequest,
                1 => {
                    let [v0, v1, flags] = take::<3>(&mut rest);
                    Message::Command(Command {
                        voltage_mv: i16::from_le_bytes([v0, v1]),
                        flags,
                    })
                }
                _ => {
                    let p = take::<17>(&mut rest);
                    let u32_at =
                        |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
                    Message::Measurement(Measurement {
                        ack_seq: u16::from_le_bytes([p[0], p[1]]),
                        arm_counts: u32_at(2) as i32,
                        pendulum_counts: u32_at(6) as i32,
                        applied_mv: i16::from_le_bytes([p[10], p[11]]),
                        status: p[12],
                        device_time_us: u32_at(13),
                    })
                }
            };
            let n = encode(&Frame { seq, message }, &mut buf);
            &buf[..n]
        } else {
            let (chunk, tail) = rest.split_at(((tag & 0x7F) as usize).min(rest.len()));
            rest = tail;
            chunk
        };
        if len + bytes.len() > stream.len() {
            break;
        }
        stream[len..len + bytes.len()].copy_from_slice(bytes);
        len += bytes.len();
    }
    let data = &stream[..len];

    let mut parser = Parser::new();
    let mut events = 0u64;
    let mut frames = [None; 256];
    let mut n_frames = 0usize;
    for (i, &b) in data.iter().enumerate() {
        parser.push(b);
        while let Some(e) = parser.poll_event() {
            events += 1;
            if let Event::Frame(f) = e {
                let mut out = [0u8; MAX_FRAME];
                let n = encode(&f, &mut out);
                // The parser buffers at most MAX_FRAME bytes: the frame lies in the last ones.
                let recent = &data[(i + 1).saturating_sub(MAX_FRAME)..=i];
                assert!(
                    recent.windows(n).any(|w| w == &out[..n]),
                    "decoded a frame that is not in the last {MAX_FRAME} bytes: {f:?}"
                );
                if n_frames < frames.len() {
                    frames[n_frames] = Some(f);
                }
                n_frames += 1;
            }
        }
    }
    let stats = parser.stats();
    assert_eq!(stats.frames + stats.errors(), events);
    assert_eq!(stats.frames, n_frames as u64);
    assert!(stats.skipped_bytes <= data.len() as u64);

    let mut whole = Parser::new();
    let mut k = 0usize;
    whole.feed(data, |f| {
        if k < frames.len() {
            assert_eq!(Some(f), frames[k]);
        }
        k += 1;
    });
    assert_eq!(k, n_frames);
    assert_eq!(whole.stats(), stats);
});

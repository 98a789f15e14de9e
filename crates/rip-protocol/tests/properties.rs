//! Property tests of the wire protocol: the parser never panics, frames round-trip, and the
//! stream resynchronises after garbage and corrupted frames.

use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rip_protocol::{
    crc16, crc32, encode, Ack, Command, Event, Frame, Measurement, Message, OnboardStart, Parser,
    PilMove, PilStep, Telemetry, UploadBegin, UploadChunk, UploadCommit, CHUNK_MAX, MAX_FRAME,
    SYNC0, SYNC1,
};

fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        (
            any::<u16>(),
            any::<i32>(),
            any::<i32>(),
            any::<i16>(),
            any::<u8>(),
            any::<u32>()
        )
            .prop_map(
                |(ack_seq, arm_counts, pendulum_counts, applied_mv, status, t)| {
                    Message::Measurement(Measurement {
                        ack_seq,
                        arm_counts,
                        pendulum_counts,
                        applied_mv,
                        status,
                        device_time_us: t,
                    })
                }
            ),
        (any::<i16>(), any::<u8>())
            .prop_map(|(voltage_mv, flags)| Message::Command(Command { voltage_mv, flags })),
        Just(Message::SampleRequest),
        v2_message(),
    ]
}

/// The messages protocol v2 added (onboard control).
fn v2_message() -> impl Strategy<Value = Message> {
    prop_oneof![
        any::<u32>().prop_map(|total_len| Message::UploadBegin(UploadBegin { total_len })),
        (
            any::<u32>(),
            proptest::collection::vec(any::<u8>(), 1..=CHUNK_MAX)
        )
            .prop_map(|(offset, data)| Message::UploadChunk(UploadChunk::new(offset, &data))),
        (any::<u32>(), any::<u32>())
            .prop_map(|(len, crc32)| Message::UploadCommit(UploadCommit { len, crc32 })),
        (
            any::<u16>(),
            any::<u16>(),
            any::<i32>(),
            any::<u32>(),
            any::<i32>(),
            any::<u32>(),
            any::<u8>()
        )
            .prop_map(|(decimation, host_timeout_ms, ac, al, pc, pl, flags)| {
                Message::OnboardStart(OnboardStart {
                    decimation,
                    host_timeout_ms,
                    arm_center: ac,
                    arm_limit: al,
                    pendulum_center: pc,
                    pendulum_limit: pl,
                    flags,
                })
            }),
        any::<u8>().prop_map(|flags| Message::OnboardStop { flags }),
        (any::<i32>(), any::<i32>(), any::<u8>()).prop_map(|(a, p, flags)| {
            Message::PilStep(PilStep {
                arm_counts: a,
                pendulum_counts: p,
                flags,
            })
        }),
        (
            any::<u16>(),
            any::<u32>(),
            any::<u64>(),
            any::<u32>(),
            any::<u8>()
        )
            .prop_map(
                |(ack_seq, step, voltage_bits, cycles, code)| Message::PilMove(PilMove {
                    ack_seq,
                    step,
                    voltage_bits,
                    cycles,
                    code
                })
            ),
        (any::<u16>(), any::<u8>(), any::<u8>(), any::<u32>()).prop_map(
            |(ack_seq, request, code, value)| Message::Ack(Ack {
                ack_seq,
                request,
                code,
                value
            })
        ),
        (
            (any::<u32>(), any::<u32>(), any::<i32>(), any::<i32>()),
            (
                any::<i16>(),
                any::<u8>(),
                any::<u8>(),
                any::<u32>(),
                any::<u16>(),
                any::<u16>()
            )
        )
            .prop_map(
                |((step, t, arm, pend), (mv, status, onboard, cycles, overruns, fallbacks))| {
                    Message::Telemetry(Telemetry {
                        step,
                        device_time_us: t,
                        arm_counts: arm,
                        pendulum_counts: pend,
                        applied_mv: mv,
                        status,
                        onboard,
                        step_cycles: cycles,
                        overruns,
                        fallbacks,
                    })
                }
            ),
    ]
}

fn frame() -> impl Strategy<Value = Frame> {
    (any::<u16>(), message()).prop_map(|(seq, message)| Frame { seq, message })
}

fn bytes_of(frame: &Frame) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(frame, &mut buf);
    buf[..n].to_vec()
}

fn parse_all(stream: &[u8]) -> (Vec<Frame>, Parser) {
    let mut parser = Parser::new();
    let mut out = Vec::new();
    parser.feed(stream, |f| out.push(f));
    (out, parser)
}

/// Line noise rich in the bytes that start a candidate frame (sync bytes, the version, small
/// length fields), so that false syncs reaching into the following real frame are common.
fn garbage() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(
        prop_oneof![
            3 => Just(SYNC0),
            2 => Just(SYNC1),
            1 => Just(1u8),
            1 => 0u8..=40,
            3 => any::<u8>(),
        ],
        0..40,
    )
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 512,
        // A corrupted frame passes CRC-16 by chance with probability 2⁻¹⁶; a fixed seed keeps
        // the suite deterministic.
        rng_seed: RngSeed::Fixed(0x5EED_F00D),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn arbitrary_bytes_never_panic(stream in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let (frames, parser) = parse_all(&stream);
        prop_assert_eq!(parser.stats().frames, frames.len() as u64);
        prop_assert!(parser.stats().skipped_bytes <= stream.len() as u64);
        // Event by event: every event is counted once, and the buffer never holds a complete
        // candidate after a poll returned `None`.
        let mut p = Parser::new();
        let mut events = 0u64;
        for &b in &stream {
            p.push(b);
            while let Some(e) = p.poll_event() {
                events += 1;
                if let Event::Frame(f) = e {
                    prop_assert!(frames.contains(&f));
                }
            }
        }
        prop_assert_eq!(p.stats().frames + p.stats().errors(), events);
        prop_assert_eq!(p.stats(), parser.stats());
    }

    #[test]
    fn noise_shaped_like_frames_never_panics(stream in garbage()) {
        let (frames, parser) = parse_all(&stream);
        prop_assert_eq!(parser.stats().frames, frames.len() as u64);
    }

    #[test]
    fn frames_round_trip(frames in proptest::collection::vec(frame(), 0..20)) {
        let stream: Vec<u8> = frames.iter().flat_map(bytes_of).collect();
        let (decoded, parser) = parse_all(&stream);
        prop_assert_eq!(&decoded, &frames);
        prop_assert_eq!(parser.stats().errors(), 0);
        prop_assert_eq!(parser.stats().skipped_bytes, 0);
    }

    #[test]
    fn every_frame_embedded_in_garbage_is_recovered(
        items in proptest::collection::vec((garbage(), frame()), 1..12),
        tail in garbage(),
    ) {
        // Holds unless a false candidate passes its CRC by chance (probability 2⁻¹⁶ per false
        // candidate); the fixed seed keeps the suite deterministic.
        let mut stream = Vec::new();
        for (garbage, f) in &items {
            stream.extend_from_slice(garbage);
            stream.extend_from_slice(&bytes_of(f));
        }
        stream.extend_from_slice(&tail);
        // The tail may be a truncated false candidate that holds back the last frame; the
        // next period's frame completes it, as on the wire.
        let flush = Frame { seq: 0, message: Message::SampleRequest };
        for _ in 0..(MAX_FRAME / 9 + 1) {
            stream.extend_from_slice(&bytes_of(&flush));
        }
        let (decoded, _) = parse_all(&stream);
        let expected: Vec<Frame> = items.iter().map(|(_, f)| *f).collect();
        prop_assert_eq!(&decoded[..expected.len()], &expected[..]);
        prop_assert!(decoded[expected.len()..].iter().all(|f| *f == flush));
    }

    #[test]
    fn a_corrupted_frame_costs_only_itself(
        frames in proptest::collection::vec(frame(), 2..12),
        which in any::<prop::sample::Index>(),
        position in any::<prop::sample::Index>(),
        flip in 1u8..=255,
    ) {
        let k = which.index(frames.len());
        let mut stream = Vec::new();
        let mut start = 0;
        for (i, f) in frames.iter().enumerate() {
            let b = bytes_of(f);
            if i == k {
                start = stream.len() + position.index(b.len());
            }
            stream.extend_from_slice(&b);
        }
        stream[start] ^= flip;
        let (decoded, parser) = parse_all(&stream);
        let expected: Vec<Frame> = frames
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != k)
            .map(|(_, f)| *f)
            .collect();
        prop_assert_eq!(decoded, expected);
        prop_assert!(parser.stats().frames == frames.len() as u64 - 1);
    }

    #[test]
    fn truncated_frames_are_dropped_and_the_following_ones_decode(
        first in frame(),
        cut in any::<prop::sample::Index>(),
        second in frame(),
        third in frame(),
    ) {
        // A truncated frame holds back the frames behind it until enough bytes have arrived
        // to complete (and reject) the truncated candidate, at most MAX_FRAME bytes; the
        // frames after that complete it, and all are then decoded.
        let a = bytes_of(&first);
        let cut = 1 + cut.index(a.len() - 1);
        let mut stream = a[..cut].to_vec();
        stream.extend_from_slice(&bytes_of(&second));
        let n = MAX_FRAME / 12 + 1;
        for _ in 0..n {
            stream.extend_from_slice(&bytes_of(&third));
        }
        let (decoded, _) = parse_all(&stream);
        let mut expected = vec![second];
        expected.extend(std::iter::repeat_n(third, n));
        prop_assert_eq!(decoded, expected);
    }
}

#[test]
fn crc_covers_version_to_payload() {
    let f = Frame {
        seq: 0xBEEF,
        message: Message::SampleRequest,
    };
    let b = bytes_of(&f);
    assert_eq!(b.len(), 9);
    assert_eq!(&b[..7], &[0xA5, 0x5A, 0x01, 0x03, 0xEF, 0xBE, 0x00]);
    assert_eq!(u16::from_le_bytes([b[7], b[8]]), crc16(&b[2..7]));
}

proptest! {
    #![proptest_config(config())]

    /// A design image split into chunks and reassembled at the chunks' offsets is the image, and
    /// its CRC-32 computed piecewise is that of the whole.
    #[test]
    fn an_image_sent_in_chunks_reassembles(image in proptest::collection::vec(any::<u8>(), 1..600)) {
        let mut stream = Vec::new();
        for (i, piece) in image.chunks(CHUNK_MAX).enumerate() {
            let f = Frame {
                seq: i as u16,
                message: Message::UploadChunk(UploadChunk::new((i * CHUNK_MAX) as u32, piece)),
            };
            stream.extend(bytes_of(&f));
        }
        let (frames, _) = parse_all(&stream);
        let mut rebuilt = vec![0u8; image.len()];
        for f in &frames {
            let Message::UploadChunk(c) = f.message else { panic!("{f:?}") };
            let at = c.offset as usize;
            rebuilt[at..at + c.bytes().len()].copy_from_slice(c.bytes());
        }
        prop_assert_eq!(frames.len(), image.len().div_ceil(CHUNK_MAX));
        prop_assert_eq!(&rebuilt, &image);
        let mut c = 0;
        for piece in image.chunks(CHUNK_MAX) {
            c = rip_protocol::crc32_update(c, piece);
        }
        prop_assert_eq!(c, crc32(&image));
    }
}

#[test]
fn v2_messages_carry_version_2_and_v1_messages_version_1() {
    let v2 = Frame {
        seq: 1,
        message: Message::OnboardStop { flags: 0 },
    };
    assert_eq!(bytes_of(&v2)[2], 2);
    let v1 = Frame {
        seq: 1,
        message: Message::Command(Command::STOP),
    };
    assert_eq!(bytes_of(&v1)[2], 1);
}

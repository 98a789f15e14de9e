//! The protocol parser on arbitrary bytes: it never panics, counts every event once, decodes
//! only frames whose exact encoding occurs in the input, and decodes the same frames whether the
//! bytes arrive one at a time or in one call.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_protocol::{encode, Event, Parser, MAX_FRAME};

fuzz_target!(|data: &[u8]| {
    let mut parser = Parser::new();
    let mut events = 0u64;
    let mut frames = [None; 64];
    let mut n_frames = 0usize;
    for &b in data {
        parser.push(b);
        while let Some(e) = parser.poll_event() {
            events += 1;
            if let Event::Frame(f) = e {
                let mut out = [0u8; MAX_FRAME];
                let n = encode(&f, &mut out);
                assert!(
                    data.windows(n).any(|w| w == &out[..n]),
                    "decoded a frame that is not in the input: {f:?}"
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

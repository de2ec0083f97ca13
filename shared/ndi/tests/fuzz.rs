//! Fuzzing: arbitrary bytes and mutated real replies into the framer, the parsers and
//! the simulated device never panic, and every rejection is counted.

mod common;

use common::{fixtures, log_exchanges, Exchange};
use proptest::prelude::*;
use sabr_ndi::bx::parse_bx_body;
use sabr_ndi::text::{parse_acknowledgement, parse_phsr};
use sabr_ndi::tx::parse_tx;
use sabr_ndi::{
    decode_reply, Command, NdiServer, RawReply, ReadError, ReplyOptions, ReplyReader, SimFrame,
    SimReading, Transform,
};
use std::sync::OnceLock;

/// Real replies: the hand-picked fixtures and every reply of the log.
fn real_replies() -> &'static [Exchange] {
    static REPLIES: OnceLock<Vec<Exchange>> = OnceLock::new();
    REPLIES.get_or_init(|| {
        let mut all = fixtures();
        all.extend(log_exchanges());
        all
    })
}

fn options() -> impl Strategy<Value = ReplyOptions> {
    (0u16..32).prop_map(|bits| {
        let mask = [0x0001, 0x0002, 0x0004, 0x0800, 0x1000]
            .into_iter()
            .enumerate()
            .filter(|(i, _)| bits & (1 << i) != 0)
            .fold(0, |acc, (_, bit)| acc | bit);
        ReplyOptions::new(mask).unwrap()
    })
}

/// Reads the whole stream; checks that every error was counted; parses every reply every way.
fn read_everything(bytes: &[u8], options: ReplyOptions) -> (u64, u64) {
    let mut reader = ReplyReader::new(bytes);
    let (mut good, mut bad) = (0, 0);
    for item in reader.by_ref() {
        match item {
            Ok(RawReply::Binary(body)) => {
                good += 1;
                let _ = parse_bx_body(&body, options);
            }
            Ok(RawReply::Text(text)) => {
                good += 1;
                let _ = parse_tx(&text, options);
                let _ = parse_phsr(&text);
                let _ = parse_acknowledgement(&text);
            }
            Err(ReadError::Reply(_)) => bad += 1,
            Err(other) => panic!("reading a slice cannot fail with {other}"),
        }
    }
    assert_eq!(reader.stats().replies, good);
    assert_eq!(
        reader.stats().bad_replies,
        bad,
        "every rejection is counted"
    );
    (good, bad)
}

/// One mutation of a byte string.
#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, u8),
    Delete(usize),
    Truncate(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(i, m)| Mutation::Flip(i, m)),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
        any::<usize>().prop_map(Mutation::Delete),
        any::<usize>().prop_map(Mutation::Truncate),
    ]
}

fn apply(bytes: &mut Vec<u8>, mutation: &Mutation) {
    if bytes.is_empty() {
        return;
    }
    let at = |i: &usize| i % bytes.len();
    match mutation {
        Mutation::Flip(i, mask) => {
            let i = at(i);
            bytes[i] ^= mask;
        }
        Mutation::Insert(i, b) => {
            let i = at(i);
            bytes.insert(i, *b);
        }
        Mutation::Delete(i) => {
            let i = at(i);
            bytes.remove(i);
        }
        Mutation::Truncate(i) => {
            let i = at(i);
            bytes.truncate(i);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600), options in options()) {
        read_everything(&bytes, options);
        let _ = decode_reply(&bytes);
        let _ = parse_bx_body(&bytes, options);
    }

    #[test]
    fn reply_shaped_bytes_never_panic(
        bytes in prop::collection::vec(prop::sample::select(b"0123456789ABCDEF+-\n\rMISNGDABLUOCPYK\xC4\xA5\x00\x01\x02\x04".to_vec()), 0..400),
        options in options(),
    ) {
        read_everything(&bytes, options);
        let text: String = bytes.iter().map(|&b| char::from(b)).collect();
        let _ = parse_tx(&text, options);
    }

    #[test]
    fn mutated_real_replies_never_panic(
        index in any::<prop::sample::Index>(),
        mutations in prop::collection::vec(mutation(), 1..4),
        options in options(),
    ) {
        let original = index.get(real_replies());
        let mut bytes = original.reply.clone();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        read_everything(&bytes, options);
        // Whatever still frames is parsed with the options of the command it answered.
        if let Ok(reply) = decode_reply(&bytes) {
            if let Ok(command) = Command::decode(original.command_text().as_bytes()) {
                match (&command, &reply) {
                    (Command::Bx(o), RawReply::Binary(body)) => {
                        let _ = parse_bx_body(body, *o);
                    }
                    (Command::Tx(o), RawReply::Text(text)) => {
                        let _ = parse_tx(text, *o);
                    }
                    _ => {}
                }
            }
        }
    }

    #[test]
    fn single_byte_corruptions_of_real_replies_are_always_caught(
        index in any::<prop::sample::Index>(),
        position in any::<prop::sample::Index>(),
        mask in 1u8..=255,
    ) {
        let original = index.get(real_replies());
        let mut bytes = original.reply.clone();
        let i = position.index(bytes.len());
        bytes[i] ^= mask;
        let (good, bad) = read_everything(&bytes, ReplyOptions::TRANSFORMS);
        prop_assert_eq!(good, 0, "a corrupted reply was accepted");
        prop_assert!(bad >= 1, "the corruption was not counted");
    }

    #[test]
    fn the_simulated_device_survives_any_input(bytes in prop::collection::vec(any::<u8>(), 0..800)) {
        let frame = SimFrame {
            frame: 9,
            readings: vec![
                SimReading::Pose(Transform { q: [1.0, 0.0, 0.0, 0.0], t: [1.0, 2.0, -3.0], rms: 0.1 }),
                SimReading::Point { position: [4.0, 5.0, -6.0], rms: 0.2 },
            ],
        };
        let mut server = NdiServer::new(2, move || Some(frame.clone()));
        // Bring it into tracking so that BX/TX paths are reachable too.
        let mut setup = Command::Init.encode();
        for command in [Command::Pinit(1), Command::Pena(1, sabr_ndi::TrackingPriority::Dynamic), Command::Tstart] {
            setup.extend(command.encode());
        }
        server.feed(&setup);
        let output = server.feed(&bytes);
        // Whatever it answered is well-formed.
        let (_, bad) = read_everything(&output, ReplyOptions::TRANSFORMS);
        prop_assert_eq!(bad, 0);
    }
}

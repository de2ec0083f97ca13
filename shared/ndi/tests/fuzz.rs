//! Fuzzing: arbitrary bytes and mutated real replies into the framer, the parsers and
//! the simulated device never panic, and every rejection is counted.

mod common;

use common::{fixtures, log_exchanges, Exchange};
use proptest::prelude::*;
use sabr_ndi::bx::parse_bx_body;
use sabr_ndi::text::{parse_acknowledgement, parse_phsr};
use sabr_ndi::tx::parse_tx;
use sabr_ndi::{
    decode_reply, Command, MeasurementVolume, NdiServer, RawReply, ReadError, ReplyOptions,
    ReplyReader, SimFrame, SimReading, Transform,
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

/// Any combination of the six reply options.
fn options() -> impl Strategy<Value = ReplyOptions> {
    (0u16..64).prop_map(|bits| {
        ReplyOptions::EACH
            .into_iter()
            .enumerate()
            .filter(|(i, _)| bits & (1 << i) != 0)
            .fold(ReplyOptions::new(0).unwrap(), |acc, (_, bit)| acc | bit)
    })
}

/// BX and TX replies of a simulated device for `options`: four tools with marker geometry in a
/// bounded volume, one disabled, one point, one pose, one outside the volume.
fn device_replies(options: ReplyOptions) -> Vec<u8> {
    let pose = |x: f32| Transform {
        q: [0.5, 0.5, -0.5, 0.5],
        t: [x, 10.0, -1500.0],
        rms: 0.1,
    };
    let frame = SimFrame {
        frame: 300,
        readings: vec![
            SimReading::Pose(pose(5.0)),
            SimReading::Pose(pose(1.0)),
            SimReading::Point {
                position: [4.0, 5.0, -1400.0],
                rms: 0.2,
            },
            SimReading::Pose(pose(2500.0)),
        ],
    };
    let volume = MeasurementVolume {
        min: [-1000.0; 3],
        max: [1000.0, 1000.0, -500.0],
    };
    let mut server = NdiServer::new(4, move || Some(frame.clone())).with_volume(volume);
    for handle in 1..=4 {
        server =
            server.with_tool_markers(handle, vec![[0.0; 3], [40.0, 0.0, 0.0], [0.0, 900.0, 0.0]]);
    }
    let mut setup = Command::Init.encode();
    for handle in 1..=4 {
        setup.extend(Command::Pinit(handle).encode());
        if handle != 2 {
            setup.extend(Command::Pena(handle, sabr_ndi::TrackingPriority::Dynamic).encode());
        }
    }
    setup.extend(Command::Tstart.encode());
    server.feed(&setup);
    let mut replies = server.feed(&Command::Bx(options).encode());
    replies.extend(server.feed(&Command::Tx(options).encode()));
    replies
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
    fn mutated_device_replies_of_every_layout_never_panic_and_are_caught(
        options in options(),
        mutations in prop::collection::vec(mutation(), 1..4),
        position in any::<prop::sample::Index>(),
        mask in 1u8..=255,
    ) {
        let original = device_replies(options);
        // Unmutated, both replies frame and parse with the options they answer.
        let mut reader = ReplyReader::new(&original[..]);
        match reader.next() {
            Some(Ok(RawReply::Binary(body))) => { parse_bx_body(&body, options).unwrap(); }
            other => panic!("BX reply: {other:?}"),
        }
        match reader.next() {
            Some(Ok(RawReply::Text(text))) => { parse_tx(&text, options).unwrap(); }
            other => panic!("TX reply: {other:?}"),
        }
        let mut bytes = original.clone();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        read_everything(&bytes, options);
        // One flipped byte: at most the other reply survives, the flip is counted.
        let mut flipped = original;
        let i = position.index(flipped.len());
        flipped[i] ^= mask;
        let (good, bad) = read_everything(&flipped, options);
        prop_assert!(good <= 1 && bad >= 1, "good {}, bad {}", good, bad);
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

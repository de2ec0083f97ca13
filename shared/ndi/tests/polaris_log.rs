//! The parser against a real NDI Polaris: every BX and TX reply of the recorded log and the
//! hand-picked replies, both kept in `tests/fixtures/`.

mod common;

use common::{fixtures, log_exchanges, parse_bin, parse_txt, Exchange, LOG_BIN, LOG_TXT};
use sabr_ndi::bx::parse_bx_body;
use sabr_ndi::text::{check_text_reply, parse_phsr};
use sabr_ndi::tx::parse_tx;
use sabr_ndi::{
    decode_reply, Command, HandleStatus, RawReply, ReplyError, ReplyOptions, ReplyReader,
    TrackingReply,
};

/// The tracking reply of a BX or TX exchange, `None` for other commands.
fn tracking(exchange: &Exchange) -> Option<Result<TrackingReply, ReplyError>> {
    let command = Command::decode(exchange.command_text().as_bytes()).ok()?;
    let parse = |options| match decode_reply(&exchange.reply)? {
        RawReply::Binary(body) if matches!(command, Command::Bx(_)) => {
            parse_bx_body(&body, options)
        }
        RawReply::Text(text) if matches!(command, Command::Tx(_)) => parse_tx(&text, options),
        other => panic!(
            "exchange {}: {other:?} does not fit {command}",
            exchange.seq
        ),
    };
    match command {
        Command::Bx(options) | Command::Tx(options) => Some(parse(options)),
        _ => None,
    }
}

fn is_bx(exchange: &Exchange) -> bool {
    exchange.command.starts_with(b"BX")
}

#[test]
fn bin_and_txt_forms_of_the_log_agree() {
    let from_bin = log_exchanges();
    let from_txt = parse_txt(LOG_TXT).unwrap();
    assert_eq!(from_bin.len(), 351, "exchanges 0-350");
    assert_eq!(from_bin, from_txt);
    // The parser of the .bin form itself rejects a cut record.
    assert!(parse_bin(&LOG_BIN[..LOG_BIN.len() - 3]).is_err());
}

#[test]
fn every_command_and_reply_of_the_log_checks_out() {
    let exchanges = log_exchanges();
    for exchange in &exchanges {
        let reply = decode_reply(&exchange.reply);
        assert!(reply.is_ok(), "exchange {}: {reply:?}", exchange.seq);
        if exchange.command.is_empty() {
            assert_eq!(reply.unwrap(), RawReply::Text("RESET".into()));
            continue;
        }
        // Our encoder reproduces every command the real host sent, CRC included.
        let command = Command::decode(exchange.command_text().as_bytes())
            .unwrap_or_else(|e| panic!("exchange {}: {e}", exchange.seq));
        assert_eq!(
            command.encode(),
            exchange.command,
            "exchange {}",
            exchange.seq
        );
    }
    let phsr: Vec<_> = exchanges
        .iter()
        .filter(|e| e.command.starts_with(b"PHSR"))
        .map(|e| parse_phsr(&decode_reply(&e.reply).unwrap().into_text().unwrap()).unwrap())
        .collect();
    assert_eq!(phsr.len(), 2);
    assert!(
        phsr[0].iter().all(|h| h.status == 0x001),
        "occupied, not initialised"
    );
    assert!(phsr[1].iter().all(|h| h.status == 0x011), "initialised");
}

#[test]
fn every_bx_and_tx_reply_of_the_log_parses() {
    let exchanges = log_exchanges();
    let replies: Vec<(&Exchange, TrackingReply)> = exchanges
        .iter()
        .filter_map(|e| {
            tracking(e).map(|r| {
                (
                    e,
                    r.unwrap_or_else(|err| panic!("exchange {}: {err}", e.seq)),
                )
            })
        })
        .collect();
    assert_eq!(replies.iter().filter(|(e, _)| is_bx(e)).count(), 151);
    assert_eq!(replies.iter().filter(|(e, _)| !is_bx(e)).count(), 151);

    for (exchange, reply) in &replies {
        let seq = exchange.seq;
        assert_eq!(reply.handles.len(), 2, "exchange {seq}");
        assert_eq!(reply.system_status, 0, "exchange {seq}");
        let (h1, h2) = (&reply.handles[0], &reply.handles[1]);
        assert_eq!((h1.handle, h2.handle), (1, 2));
        if !reply.options.contains(ReplyOptions::TRANSFORMS) {
            // 0x1000 alone: BX still carries the status byte, TX no status at all.
            let expected = if is_bx(exchange) {
                [HandleStatus::Missing, HandleStatus::Valid]
            } else {
                [HandleStatus::NotReported; 2]
            };
            assert_eq!([h1.status, h2.status], expected, "exchange {seq}");
            assert!(h1.frame.is_none() && h1.transform.is_none());
            continue;
        }
        // Handle 1 (UNKNOWN tool) is never seen; handle 2 is seen from exchange 48 on.
        assert_eq!(h1.status, HandleStatus::Missing, "exchange {seq}");
        assert_eq!(h1.transform, None);
        let expected = if seq < 48 {
            HandleStatus::Missing
        } else {
            HandleStatus::Valid
        };
        assert_eq!(h2.status, expected, "exchange {seq}");
        assert_eq!(h2.transform.is_some(), seq >= 48);
        for h in [h1, h2] {
            assert_eq!(
                h.port_status,
                Some(0x31),
                "occupied | initialised | enabled"
            );
        }
        if let Some(t) = h2.transform {
            let norm = t.q.iter().map(|q| q * q).sum::<f32>().sqrt();
            let tolerance = if is_bx(exchange) { 1e-5 } else { 2e-4 };
            assert!(
                (norm - 1.0).abs() < tolerance,
                "exchange {seq}: |q| = {norm}"
            );
            assert!(
                t.t[2] < -2000.0 && t.t[2] > -2300.0,
                "exchange {seq}: z = {}",
                t.t[2]
            );
            assert!(
                t.rms > 0.0 && t.rms < 0.2,
                "exchange {seq}: rms = {}",
                t.rms
            );
        }
        let single_stray = reply.options.contains(ReplyOptions::SINGLE_STRAY);
        for h in [h1, h2] {
            assert_eq!(h.active_marker.is_some(), single_stray);
            if let Some(marker) = h.active_marker {
                assert_eq!(
                    (marker.status, marker.position),
                    (0, None),
                    "exchange {seq}"
                );
            }
        }
    }
    check_frame_numbers(&replies);
    check_stray_markers(&replies);
    check_tool_info(&replies);
}

/// Per handle, frame numbers never go back; within a run of identical commands each step is
/// 0 or +3 for BX (polled faster than the camera) and exactly +3 for TX.
fn check_frame_numbers(replies: &[(&Exchange, TrackingReply)]) {
    let mut steps = [0usize; 2];
    for handle_index in 0..2 {
        let mut previous: Option<(&Exchange, u32)> = None;
        for (exchange, reply) in replies {
            let Some(frame) = reply.handles[handle_index].frame else {
                continue;
            };
            if let Some((prev_exchange, prev_frame)) = previous {
                assert!(
                    frame >= prev_frame,
                    "exchange {}: frame went back",
                    exchange.seq
                );
                let same_run = prev_exchange.command == exchange.command
                    && prev_exchange.seq + 1 == exchange.seq;
                if same_run && prev_frame != 0 {
                    let step = frame - prev_frame;
                    if is_bx(exchange) {
                        assert!(
                            step == 0 || step == 3,
                            "exchange {}: BX step {step}",
                            exchange.seq
                        );
                    } else {
                        assert_eq!(step, 3, "exchange {}: TX step", exchange.seq);
                    }
                    steps[usize::from(step == 3)] += 1;
                }
            }
            previous = Some((exchange, frame));
        }
    }
    // Both kinds of step occur: repeats (BX only) and advances of 3.
    assert!(steps[0] > 20 && steps[1] > 200, "steps {steps:?}");
    // Hand-read from the log: TX:0001 at exchange 192 carries frames 0x24B and 0x24A.
    let tx192 = &replies.iter().find(|(e, _)| e.seq == 192).unwrap().1;
    assert_eq!(
        (tx192.handles[0].frame, tx192.handles[1].frame),
        (Some(0x24B), Some(0x24A))
    );
    assert_eq!(tx192.frame(), Some(0x24B));
}

/// The three stray passive markers stand still: BX and TX report them within 0.5 mm.
fn check_stray_markers(replies: &[(&Exchange, TrackingReply)]) {
    let sets: Vec<_> = replies
        .iter()
        .filter_map(|(_, r)| r.stray_markers.as_ref())
        .collect();
    assert_eq!(sets.len(), 100);
    // Hand-read from exchange 242 (TX:1000): +015360+030698-223261 ...
    let reference = [
        [153.60, 306.98, -2232.61],
        [151.73, 221.99, -2255.96],
        [71.59, 267.25, -2274.15],
    ];
    for set in sets {
        assert_eq!(set.len(), 3);
        for (marker, expected) in set.iter().zip(reference) {
            assert!(!marker.out_of_volume);
            let p = marker.position;
            for axis in 0..3 {
                assert!(
                    (p[axis] - expected[axis]).abs() < 0.5,
                    "{p:?} vs {expected:?}"
                );
            }
        }
    }
}

/// Exchanges 191 (BX:0003) and 342 (TX:0003) carry the same tool and marker information.
fn check_tool_info(replies: &[(&Exchange, TrackingReply)]) {
    let info = |seq| {
        let reply = &replies.iter().find(|(e, _)| e.seq == seq).unwrap().1;
        [
            reply.handles[0].tool_info.unwrap(),
            reply.handles[1].tool_info.unwrap(),
        ]
    };
    for seq in [191, 342] {
        let [h1, h2] = info(seq);
        assert_eq!((h1.tool, h1.markers), (0x02, [0; 10]), "exchange {seq}");
        assert_eq!(h2.tool, 0x00);
        assert_eq!(
            h2.markers,
            [0, 0, 0, 0, 0x03, 0, 0, 0x30, 0, 0x03],
            "exchange {seq}"
        );
    }
}

/// Poses decoded by hand from the raw bytes (BX little-endian floats) and the text (TX).
fn check_hand_verified(exchange: &Exchange, reply: &TrackingReply) {
    let t = reply.handles[1].transform.unwrap();
    match exchange.seq {
        48 => {
            // Bytes 7F 28 0F 3F ... of the body: q0 = 0x3F0F287F, ...
            let bits = [
                0x3F0F287F, 0x3F1D1280, 0x3EC61D20, 0x3ECD80A2, 0xC2B1781C, 0x4324D4D8, 0xC5097FC8,
                0x3D0A5FC5,
            ];
            let v: Vec<f32> = bits.iter().map(|&b| f32::from_bits(b)).collect();
            assert_eq!(t.q, [v[0], v[1], v[2], v[3]]);
            assert_eq!(t.t, [v[4], v[5], v[6]]);
            assert_eq!(t.rms, v[7]);
            assert!((t.q[0] - 0.559_21).abs() < 1e-5 && (t.t[0] + 88.7346).abs() < 1e-3);
            assert!((t.t[2] + 2199.9863).abs() < 1e-3 && (t.rms - 0.033_78).abs() < 1e-5);
            assert_eq!(reply.handles[1].frame, Some(0x12A));
        }
        192 => {
            // 02+05029+04875+04692+05377-008481+014804-210619+00356 00000031 0000024A
            assert_eq!(t.q, [0.5029, 0.4875, 0.4692, 0.5377]);
            assert_eq!(t.t, [-84.81, 148.04, -2106.19]);
            assert_eq!(t.rms, 0.0356);
        }
        342 => {
            // 02+05036+04469+04825+05601-005056+010437-202772+00180
            assert_eq!(t.q, [0.5036, 0.4469, 0.4825, 0.5601]);
            assert_eq!(t.t, [-50.56, 104.37, -2027.72]);
            assert_eq!(t.rms, 0.0180);
            assert_eq!(reply.handles[1].frame, Some(0x40C));
        }
        _ => {}
    }
}

#[test]
fn hand_verified_poses_from_the_log_and_the_fixtures() {
    for (name, exchanges) in [("fixtures", fixtures()), ("log", log_exchanges())] {
        let mut checked = 0;
        for exchange in exchanges.iter().filter(|e| [48, 192, 342].contains(&e.seq)) {
            check_hand_verified(exchange, &tracking(exchange).unwrap().unwrap());
            checked += 1;
        }
        assert_eq!(checked, 3, "{name}");
    }
}

#[test]
fn fixtures_parse_like_the_device_meant() {
    let exchanges = fixtures();
    assert_eq!(exchanges.len(), 14);
    for exchange in &exchanges {
        match tracking(exchange) {
            Some(reply) => {
                let reply = reply.unwrap_or_else(|e| panic!("fixture {}: {e}", exchange.seq));
                assert_eq!(reply.handles.len(), 2);
            }
            None => assert!(
                decode_reply(&exchange.reply).is_ok(),
                "fixture {}",
                exchange.seq
            ),
        }
    }
    let ver = exchanges.iter().find(|e| e.seq == 4).unwrap();
    let text = decode_reply(&ver.reply).unwrap().into_text().unwrap();
    assert!(text.contains("Freeze Tag: POLARIS Rev 020\n"), "{text}");
    let stray = exchanges.iter().find(|e| e.seq == 91).unwrap();
    let strays = tracking(stray).unwrap().unwrap().stray_markers.unwrap();
    assert_eq!(strays.len(), 3);
}

/// Every single-byte corruption of `reply` (one mask per position) must be rejected.
fn assert_every_flip_rejected(seq: u32, reply: &[u8]) -> usize {
    let masks = [0x01u8, 0x80, 0xFF, 0x20, 0x10];
    for (i, mask) in masks.iter().cycle().take(reply.len()).enumerate() {
        let mut corrupted = reply.to_vec();
        corrupted[i] ^= mask;
        let result = decode_reply(&corrupted);
        assert!(
            result.is_err(),
            "exchange {seq}: flipping byte {i} with {mask:#04x} went unnoticed: {result:?}"
        );
    }
    reply.len()
}

#[test]
fn corrupted_replies_are_rejected_by_crc() {
    let mut flipped = 0;
    for exchange in fixtures() {
        flipped += assert_every_flip_rejected(exchange.seq, &exchange.reply);
    }
    let exchanges = log_exchanges();
    for exchange in &exchanges {
        flipped += assert_every_flip_rejected(exchange.seq, &exchange.reply);
    }
    assert!(flipped > 25_000, "{flipped} corrupted replies");
    // The CRC error names both values.
    let mut okay = b"OKAYA896\r".to_vec();
    okay[0] = b'0';
    assert!(matches!(
        decode_reply(&okay),
        Err(ReplyError::BadCrc { actual: 0xA896, .. })
    ));
    let bx = &exchanges.iter().find(|e| e.seq == 48).unwrap().reply;
    let mut body_flip = bx.clone();
    body_flip[20] ^= 0x04;
    assert!(matches!(
        decode_reply(&body_flip),
        Err(ReplyError::BadCrc { .. })
    ));
    let mut header_flip = bx.clone();
    header_flip[2] ^= 0x04;
    assert!(matches!(
        decode_reply(&header_flip),
        Err(ReplyError::BadHeaderCrc { .. })
    ));
}

#[test]
fn the_whole_received_stream_through_the_reply_reader() {
    let exchanges = log_exchanges();
    let stream: Vec<u8> = exchanges.iter().flat_map(|e| e.reply.clone()).collect();
    let expected: Vec<RawReply> = exchanges
        .iter()
        .map(|e| decode_reply(&e.reply).unwrap())
        .collect();
    let mut reader = ReplyReader::new(&stream[..]);
    let got: Vec<RawReply> = reader.by_ref().map(|r| r.unwrap()).collect();
    assert_eq!(got, expected);
    assert_eq!(
        (reader.stats().replies, reader.stats().bad_replies),
        (351, 0)
    );

    // One corrupted byte anywhere: that reply (and at most the one after it) is lost, every
    // accepted reply is a genuine one in order, and the loss is counted.
    for position in (0..stream.len()).step_by(97) {
        let mut corrupted = stream.clone();
        corrupted[position] ^= 0x5A;
        let mut reader = ReplyReader::new(&corrupted[..]);
        let good: Vec<RawReply> = reader.by_ref().filter_map(Result::ok).collect();
        assert!(
            good.len() >= expected.len() - 2,
            "byte {position}: only {} replies",
            good.len()
        );
        assert!(
            good.len() < expected.len(),
            "byte {position}: corruption went unnoticed"
        );
        let mut rest = expected.iter();
        for reply in &good {
            assert!(
                rest.any(|e| e == reply),
                "byte {position}: accepted a reply that was never sent"
            );
        }
        assert!(reader.stats().bad_replies >= 1);
    }
    // A check of the helper used above: text replies carry their CRC.
    assert!(check_text_reply(b"OKAYA896").is_ok());
}

//! The simulated device's BX/TX replies, parsed by the host side, give back the rig's frame.

use proptest::prelude::*;
use sabr_ndi::bx::parse_bx_frame;
use sabr_ndi::text::parse_acknowledgement;
use sabr_ndi::tx::parse_tx;
use sabr_ndi::{
    decode_reply, Command, HandleStatus, NdiServer, ReplyOptions, SimFrame, SimReading,
    TrackingPriority, Transform,
};

fn reading() -> impl Strategy<Value = SimReading> {
    let coordinate = -3000.0f32..3000.0;
    prop_oneof![
        Just(SimReading::Missing),
        (
            prop::array::uniform4(-1.0f32..1.0),
            prop::array::uniform3(coordinate.clone()),
            0.0f32..2.0
        )
            .prop_map(|(q, t, rms)| SimReading::Pose(Transform { q, t, rms })),
        (prop::array::uniform3(coordinate), 0.0f32..2.0)
            .prop_map(|(position, rms)| SimReading::Point { position, rms }),
    ]
}

/// The pose the device reports for a reading (points: identity quaternion).
fn expected(reading: &SimReading) -> Option<Transform> {
    match *reading {
        SimReading::Missing => None,
        SimReading::Pose(t) => Some(t),
        SimReading::Point { position, rms } => Some(Transform {
            q: [1.0, 0.0, 0.0, 0.0],
            t: position,
            rms,
        }),
    }
}

proptest! {
    #[test]
    fn served_frames_parse_back(frame in any::<u32>(), readings in prop::collection::vec(reading(), 4)) {
        let sim = SimFrame { frame, readings: readings.clone() };
        let mut server = NdiServer::new(4, move || Some(sim.clone()));
        let mut ask = |command: Command| decode_reply(&server.feed(&command.encode())).unwrap();
        for command in [Command::Init, Command::Pinit(1), Command::Pinit(2), Command::Pinit(3), Command::Pinit(4)] {
            parse_acknowledgement(&ask(command).into_text().unwrap()).unwrap();
        }
        for handle in 1..=4 {
            parse_acknowledgement(&ask(Command::Pena(handle, TrackingPriority::Dynamic)).into_text().unwrap()).unwrap();
        }
        parse_acknowledgement(&ask(Command::Tstart).into_text().unwrap()).unwrap();

        let options = ReplyOptions::TRANSFORMS | ReplyOptions::OUT_OF_VOLUME | ReplyOptions::PASSIVE_STRAYS;
        let sabr_ndi::RawReply::Binary(body) = ask(Command::Bx(options)) else { panic!("BX answered with text") };
        let bx = sabr_ndi::bx::parse_bx_body(&body, options).unwrap();
        let tx = parse_tx(&ask(Command::Tx(options)).into_text().unwrap(), options).unwrap();
        for (i, reading) in readings.iter().enumerate() {
            let want = expected(reading);
            let (b, t) = (&bx.handles[i], &tx.handles[i]);
            prop_assert_eq!(b.handle as usize, i + 1);
            prop_assert_eq!(b.frame, Some(frame));
            prop_assert_eq!(t.frame, Some(frame));
            prop_assert_eq!(b.status, if want.is_some() { HandleStatus::Valid } else { HandleStatus::Missing });
            prop_assert_eq!(t.status, b.status);
            prop_assert_eq!(b.transform, want);
            if let (Some(got), Some(want)) = (t.transform, want) {
                for k in 0..4 { prop_assert!((got.q[k] - want.q[k]).abs() <= 1e-4); }
                for k in 0..3 { prop_assert!((got.t[k] - want.t[k]).abs() <= 1e-2); }
                prop_assert!((got.rms - want.rms).abs() <= 1e-4);
            }
        }
        let points: Vec<[f32; 3]> = readings.iter().filter_map(|r| match r { SimReading::Point { position, .. } => Some(*position), _ => None }).collect();
        let strays: Vec<[f32; 3]> = bx.stray_markers.unwrap().iter().map(|m| m.position.unwrap()).collect();
        prop_assert_eq!(strays, points);
        // The same frame through the full-frame BX parser.
        let bytes = server_bytes(frame, &readings, options);
        prop_assert_eq!(parse_bx_frame(&bytes, options).unwrap().frame(), Some(frame));
    }
}

/// The raw BX bytes of a freshly started server for one frame.
fn server_bytes(frame: u32, readings: &[SimReading], options: ReplyOptions) -> Vec<u8> {
    let sim = SimFrame {
        frame,
        readings: readings.to_vec(),
    };
    let mut server = NdiServer::new(4, move || Some(sim.clone()));
    let mut setup = Command::Init.encode();
    for handle in 1..=4 {
        setup.extend(Command::Pinit(handle).encode());
        setup.extend(Command::Pena(handle, TrackingPriority::Dynamic).encode());
    }
    setup.extend(Command::Tstart.encode());
    let acks = server.feed(&setup);
    assert_eq!(acks, b"OKAYA896\r".repeat(10));
    server.feed(&Command::Bx(options).encode())
}

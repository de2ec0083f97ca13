//! The simulated device's BX/TX replies, parsed by the host side, give back the rig's frame:
//! for every combination of the six reply options, with enabled and disabled handles in any
//! position, tools in and out of a bounded measurement volume.

use proptest::prelude::*;
use sabr_ndi::bx::{parse_bx_body, parse_bx_frame};
use sabr_ndi::text::parse_acknowledgement;
use sabr_ndi::tx::parse_tx;
use sabr_ndi::{
    decode_reply, ActiveMarker, Command, HandleReading, HandleStatus, MarkerPosition,
    MeasurementVolume, NdiServer, RawReply, ReplyOptions, SimFrame, SimReading, TrackingPriority,
    TrackingReply, Transform,
};

const VOLUME: MeasurementVolume = MeasurementVolume {
    min: [-1000.0, -1000.0, -2500.0],
    max: [1000.0, 1000.0, -500.0],
};

/// The marker geometry of tool `handle` in its own frame (mm): 3 or 4 markers.
fn geometry(handle: u8) -> Vec<[f32; 3]> {
    let s = 20.0 * f32::from(handle);
    let mut markers = vec![[0.0, 0.0, 0.0], [s, 0.0, 0.0], [0.0, s, 10.0]];
    if handle.is_multiple_of(2) {
        markers.push([-s, 5.0, 0.0]);
    }
    markers
}

fn reading() -> impl Strategy<Value = SimReading> {
    let position =
        (-1500.0f32..1500.0, -1500.0f32..1500.0, -3000.0f32..0.0).prop_map(|(x, y, z)| [x, y, z]);
    prop_oneof![
        Just(SimReading::Missing),
        (
            prop::array::uniform4(-1.0f32..1.0),
            position.clone(),
            0.0f32..2.0
        )
            .prop_filter("a rotation", |(q, _, _)| q
                .iter()
                .map(|v| v * v)
                .sum::<f32>()
                > 0.01)
            .prop_map(|(q, t, rms)| SimReading::Pose(Transform { q, t, rms })),
        (position, 0.0f32..2.0).prop_map(|(position, rms)| SimReading::Point { position, rms }),
    ]
}

fn options() -> impl Strategy<Value = ReplyOptions> {
    (0u16..64).prop_map(|bits| {
        ReplyOptions::EACH
            .into_iter()
            .enumerate()
            .filter(|(i, _)| bits & (1 << i) != 0)
            .fold(ReplyOptions::new(0).unwrap(), |acc, (_, bit)| acc | bit)
    })
}

/// `p` rotated by the unit quaternion of `q` (Hamilton product q·p·q*) and moved by `t`.
fn placed(q: [f32; 4], t: [f32; 3], p: [f32; 3]) -> [f32; 3] {
    let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    let [w, x, y, z] = q.map(|v| v / n);
    let mul = |a: [f32; 4], b: [f32; 4]| {
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    };
    let r = mul(mul([w, x, y, z], [0.0, p[0], p[1], p[2]]), [w, -x, -y, -z]);
    [r[1] + t[0], r[2] + t[1], r[3] + t[2]]
}

fn near(a: [f32; 3], b: [f32; 3], tolerance: f32) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tolerance)
}

/// A started device with 4 tools, handles `enabled[i]` enabled and the others only initialised.
fn device(frame: SimFrame, enabled: [bool; 4]) -> NdiServer<impl FnMut() -> Option<SimFrame>> {
    let mut server = NdiServer::new(4, move || Some(frame.clone())).with_volume(VOLUME);
    for handle in 1..=4 {
        server = server.with_tool_markers(handle, geometry(handle));
    }
    let mut setup = Command::Init.encode();
    for handle in 1..=4u8 {
        setup.extend(Command::Pinit(handle).encode());
        if enabled[usize::from(handle) - 1] {
            setup.extend(Command::Pena(handle, TrackingPriority::Dynamic).encode());
        }
    }
    setup.extend(Command::Tstart.encode());
    let acks = server.feed(&setup);
    let count = 6 + enabled.iter().filter(|&&e| e).count();
    assert_eq!(acks, b"OKAYA896\r".repeat(count));
    server
}

/// Checks one handle of a BX reply against the reading the rig gave the device.
fn check_handle(h: &HandleReading, reading: &SimReading, enabled: bool, options: ReplyOptions) {
    let all = options.contains(ReplyOptions::OUT_OF_VOLUME);
    if !enabled {
        assert_eq!(h.status, HandleStatus::Disabled);
        assert!(h.transform.is_none() && h.tool_info.is_none() && h.tool_markers.is_none());
        return;
    }
    let (pose, markers): (Option<Transform>, Vec<[f32; 3]>) = match *reading {
        SimReading::Missing => (None, vec![]),
        SimReading::Pose(t) => (
            Some(t),
            geometry(h.handle)
                .into_iter()
                .map(|p| placed(t.q, t.t, p))
                .collect(),
        ),
        SimReading::Point { position, rms } => (
            Some(Transform {
                q: [1.0, 0.0, 0.0, 0.0],
                t: position,
                rms,
            }),
            vec![position],
        ),
    };
    let inside = pose.is_none_or(|t| VOLUME.contains(t.t));
    let seen = pose.is_some() && (inside || all);
    assert_eq!(
        h.status == HandleStatus::Valid,
        seen,
        "{h:?} for {reading:?}"
    );
    if options.contains(ReplyOptions::TRANSFORMS) {
        assert_eq!(h.transform, pose.filter(|_| seen));
        let port = h.port_status.unwrap();
        assert_eq!(port & 0x31, 0x31, "occupied, initialised, enabled");
        assert_eq!(
            port & 0x40 != 0,
            pose.is_some() && !inside,
            "out of volume bit"
        );
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        let info = h.tool_info.unwrap();
        assert_eq!(info.tool, if seen { 0x00 } else { 0x02 });
        let used: u32 = info
            .markers
            .iter()
            .map(|b| (b & 0x0F == 3) as u32 + (b >> 4 == 3) as u32)
            .sum();
        assert_eq!(used as usize, if seen { markers.len() } else { 0 });
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let marker = h.active_marker.unwrap();
        match *reading {
            SimReading::Point { position, .. } => {
                let in_volume = VOLUME.contains(position);
                assert_eq!(marker.status & ActiveMarker::VALID, ActiveMarker::VALID);
                assert_eq!(marker.status & ActiveMarker::OUT_OF_VOLUME != 0, !in_volume);
                assert_eq!(marker.position, (in_volume || all).then_some(position));
            }
            _ => assert_eq!(
                marker,
                ActiveMarker {
                    status: ActiveMarker::MISSING,
                    position: None
                }
            ),
        }
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        let expected: Vec<[f32; 3]> = markers
            .into_iter()
            .filter(|&p| all || VOLUME.contains(p))
            .collect();
        let got = h.tool_markers.as_ref().unwrap();
        assert_eq!(got.len(), expected.len(), "{got:?} vs {expected:?}");
        for (m, p) in got.iter().zip(&expected) {
            assert!(near(m.position, *p, 1e-2), "{m:?} vs {p:?}");
            assert_eq!(m.out_of_volume, !VOLUME.contains(*p));
        }
    }
}

/// The TX reply says what the BX reply says, to the TX format's precision.
fn assert_tx_matches_bx(tx: &TrackingReply, bx: &TrackingReply) {
    assert_eq!(tx.handles.len(), bx.handles.len());
    for (t, b) in tx.handles.iter().zip(&bx.handles) {
        assert_eq!(t.handle, b.handle);
        if bx.options.contains(ReplyOptions::TRANSFORMS) || b.status == HandleStatus::Disabled {
            assert_eq!(t.status, b.status);
        } else {
            assert_eq!(t.status, HandleStatus::NotReported, "TX carries no status");
        }
        assert_eq!(
            (t.port_status, t.frame, t.tool_info),
            (b.port_status, b.frame, b.tool_info)
        );
        assert_eq!(t.transform.is_some(), b.transform.is_some());
        if let (Some(tt), Some(bt)) = (t.transform, b.transform) {
            assert!(near(tt.t, bt.t, 1e-2) && (tt.rms - bt.rms).abs() <= 1e-4);
        }
        assert_eq!(
            t.active_marker.map(|m| m.status),
            b.active_marker.map(|m| m.status)
        );
        let markers = |r: &HandleReading| r.tool_markers.clone().unwrap_or_default();
        assert_marker_lists(&markers(t), &markers(b));
    }
    assert_marker_lists(
        tx.stray_markers.as_deref().unwrap_or_default(),
        bx.stray_markers.as_deref().unwrap_or_default(),
    );
}

fn assert_marker_lists(a: &[MarkerPosition], b: &[MarkerPosition]) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.out_of_volume, y.out_of_volume);
        assert!(near(x.position, y.position, 1e-2));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn served_frames_parse_back_with_every_option(
        frame in any::<u32>(),
        readings in prop::collection::vec(reading(), 4),
        enabled in any::<[bool; 4]>(),
        options in options(),
    ) {
        let sim = SimFrame { frame, readings: readings.clone() };
        let mut server = device(sim, enabled);
        let RawReply::Binary(body) = decode_reply(&server.feed(&Command::Bx(options).encode())).unwrap()
        else { panic!("BX answered with text") };
        let bx = parse_bx_body(&body, options).unwrap();
        prop_assert_eq!(bx.handles.len(), 4, "every initialised handle is reported");
        for (i, h) in bx.handles.iter().enumerate() {
            prop_assert_eq!(usize::from(h.handle), i + 1);
            check_handle(h, &readings[i], enabled[i], options);
            if options.contains(ReplyOptions::TRANSFORMS) && enabled[i] {
                prop_assert_eq!(h.frame, Some(frame));
            }
        }
        let points: Vec<[f32; 3]> = readings
            .iter()
            .filter_map(|r| match r { SimReading::Point { position, .. } => Some(*position), _ => None })
            .filter(|&p| options.contains(ReplyOptions::OUT_OF_VOLUME) || VOLUME.contains(p))
            .collect();
        if options.contains(ReplyOptions::PASSIVE_STRAYS) {
            let strays: Vec<[f32; 3]> = bx.stray_markers.clone().unwrap().iter().map(|m| m.position).collect();
            prop_assert_eq!(strays, points);
        } else {
            prop_assert!(bx.stray_markers.is_none());
        }
        let text = decode_reply(&server.feed(&Command::Tx(options).encode())).unwrap().into_text().unwrap();
        let tx = parse_tx(&text, options).unwrap();
        assert_tx_matches_bx(&tx, &bx);
    }
}

#[test]
fn the_full_bx_frame_parses_like_its_body() {
    let sim = SimFrame {
        frame: 77,
        readings: vec![SimReading::Missing; 4],
    };
    let mut server = device(sim, [true, false, true, true]);
    let options = ReplyOptions::TRANSFORMS | ReplyOptions::TOOL_MARKERS;
    let bytes = server.feed(&Command::Bx(options).encode());
    let reply = parse_bx_frame(&bytes, options).unwrap();
    assert_eq!(reply.frame(), Some(77));
    assert_eq!(reply.handles[1].status, HandleStatus::Disabled);
    assert!(parse_acknowledgement(
        &decode_reply(&server.feed(&Command::Tstop.encode()))
            .unwrap()
            .into_text()
            .unwrap()
    )
    .is_ok());
}

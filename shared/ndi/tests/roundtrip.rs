//! Device-side encoding → host-side parsing gives back the same values: BX exactly (f32), TX to
//! its precision (1e-4 for quaternions and rms, 1e-2 mm for positions), for every combination of
//! the six reply options, with valid, MISSING and DISABLED handles in any position.

use proptest::prelude::*;
use sabr_ndi::bx::{encode_bx, parse_bx_frame};
use sabr_ndi::tx::{encode_tx, parse_tx};
use sabr_ndi::{
    decode_reply, ActiveMarker, HandleReading, HandleStatus, MarkerPosition, ReplyOptions,
    ToolInfo, TrackingReply, Transform,
};

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

/// A marker list of 0 to 20 markers (the most a tool has), some out of volume.
fn markers() -> impl Strategy<Value = Vec<MarkerPosition>> {
    prop::collection::vec(
        (point(), any::<bool>()).prop_map(|(position, out_of_volume)| MarkerPosition {
            position,
            out_of_volume,
        }),
        0..21,
    )
}

fn point() -> impl Strategy<Value = [f32; 3]> {
    prop::array::uniform3(-9000.0f32..9000.0)
}

fn transform() -> impl Strategy<Value = Transform> {
    (prop::array::uniform4(-1.0f32..1.0), point(), 0.0f32..9.0).prop_map(|(q, t, rms)| Transform {
        q,
        t,
        rms,
    })
}

/// Everything a handle could carry; [`consistent`] keeps what options and status call for.
#[derive(Debug, Clone)]
struct RawHandle {
    status: u8,
    transform: Transform,
    port_status: u32,
    frame: u32,
    tool_info: ToolInfo,
    marker_status: u8,
    marker_position: [f32; 3],
    tool_markers: Vec<MarkerPosition>,
}

fn raw_handle() -> impl Strategy<Value = RawHandle> {
    (
        0u8..3,
        transform(),
        any::<u32>(),
        any::<u32>(),
        any::<u8>(),
        any::<[u8; 10]>(),
        prop_oneof![
            Just(ActiveMarker::MISSING),
            Just(ActiveMarker::VALID),
            Just(ActiveMarker::VALID | ActiveMarker::OUT_OF_VOLUME),
            any::<u8>()
        ],
        point(),
        markers(),
    )
        .prop_map(
            |(
                status,
                transform,
                port_status,
                frame,
                tool,
                markers,
                marker_status,
                marker_position,
                tool_markers,
            )| RawHandle {
                status,
                transform,
                port_status,
                frame,
                tool_info: ToolInfo { tool, markers },
                marker_status,
                marker_position,
                tool_markers,
            },
        )
}

fn consistent(handle: u8, raw: &RawHandle, options: ReplyOptions, text: bool) -> HandleReading {
    let transforms = options.contains(ReplyOptions::TRANSFORMS);
    let status = match raw.status {
        2 => HandleStatus::Disabled,
        _ if text && !transforms => HandleStatus::NotReported,
        0 => HandleStatus::Valid,
        _ => HandleStatus::Missing,
    };
    let mut reading = HandleReading::bare(handle, status);
    if status == HandleStatus::Disabled {
        return reading;
    }
    if transforms {
        reading.transform = (status == HandleStatus::Valid).then_some(raw.transform);
        reading.port_status = Some(raw.port_status);
        reading.frame = Some(raw.frame);
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        reading.tool_info = Some(raw.tool_info);
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let position = ActiveMarker::carries_position(raw.marker_status, options)
            .then_some(raw.marker_position);
        reading.active_marker = Some(ActiveMarker {
            status: raw.marker_status,
            position,
        });
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        reading.tool_markers = Some(raw.tool_markers.clone());
    }
    reading
}

fn reply(text: bool) -> impl Strategy<Value = TrackingReply> {
    (
        options(),
        prop::collection::vec(raw_handle(), 0..6),
        prop::collection::vec((point(), any::<bool>()), 0..40),
        any::<u16>(),
    )
        .prop_map(move |(options, raw, strays, system_status)| {
            let handles = raw
                .iter()
                .enumerate()
                .map(|(i, r)| consistent(i as u8 + 1, r, options, text))
                .collect();
            let stray_markers = options.contains(ReplyOptions::PASSIVE_STRAYS).then(|| {
                strays
                    .iter()
                    .map(|&(position, out_of_volume)| MarkerPosition {
                        position,
                        out_of_volume,
                    })
                    .collect()
            });
            TrackingReply {
                options,
                handles,
                stray_markers,
                system_status,
            }
        })
}

fn close(a: &[f32], b: &[f32], tolerance: f32) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tolerance)
}

fn assert_markers_close(parsed: &[MarkerPosition], original: &[MarkerPosition]) {
    assert_eq!(parsed.len(), original.len());
    for (a, b) in parsed.iter().zip(original) {
        assert_eq!(a.out_of_volume, b.out_of_volume);
        assert!(close(&a.position, &b.position, 1e-2), "{a:?} vs {b:?}");
    }
}

/// Parsed TX equals the original up to the format's precision (plus f32 rounding).
fn assert_tx_close(parsed: &TrackingReply, original: &TrackingReply) {
    assert_eq!(parsed.handles.len(), original.handles.len());
    for (p, o) in parsed.handles.iter().zip(&original.handles) {
        assert_eq!(
            (p.handle, p.status, p.port_status, p.frame, p.tool_info),
            (o.handle, o.status, o.port_status, o.frame, o.tool_info)
        );
        assert_eq!(p.transform.is_some(), o.transform.is_some());
        if let (Some(pt), Some(ot)) = (p.transform, o.transform) {
            assert!(close(&pt.q, &ot.q, 1e-4), "{pt:?} vs {ot:?}");
            assert!(close(&pt.t, &ot.t, 1e-2), "{pt:?} vs {ot:?}");
            assert!(close(&[pt.rms], &[ot.rms], 1e-4), "{pt:?} vs {ot:?}");
        }
        match (p.active_marker, o.active_marker) {
            (Some(pm), Some(om)) => {
                assert_eq!(pm.status, om.status);
                assert_eq!(pm.position.is_some(), om.position.is_some());
                if let (Some(a), Some(b)) = (pm.position, om.position) {
                    assert!(close(&a, &b, 1e-2));
                }
            }
            (pm, om) => assert_eq!(pm.is_some(), om.is_some()),
        }
        match (&p.tool_markers, &o.tool_markers) {
            (Some(pm), Some(om)) => assert_markers_close(pm, om),
            (pm, om) => assert_eq!(pm.is_some(), om.is_some()),
        }
    }
    match (&parsed.stray_markers, &original.stray_markers) {
        (Some(ps), Some(os)) => assert_markers_close(ps, os),
        (ps, os) => assert_eq!(ps.is_some(), os.is_some()),
    }
    assert_eq!(parsed.system_status, original.system_status);
}

proptest! {
    #[test]
    fn bx_round_trip_is_exact(original in reply(false)) {
        let frame = encode_bx(&original).unwrap();
        let parsed = parse_bx_frame(&frame, original.options).unwrap();
        prop_assert_eq!(parsed, original);
    }

    #[test]
    fn tx_round_trip_keeps_the_format_precision(original in reply(true)) {
        let bytes = encode_tx(&original).unwrap();
        let text = decode_reply(&bytes).unwrap().into_text().unwrap();
        let parsed = parse_tx(&text, original.options).unwrap();
        assert_tx_close(&parsed, &original);
    }
}

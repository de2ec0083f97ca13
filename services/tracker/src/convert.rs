//! Tracking replies of the NDI driver as graph messages: which port handle is which tool,
//! and one [`TrackerFrame`] per new frame.

use std::str::FromStr;

use sabr_msgs::{Tool, ToolSample, ToolStatus, TrackerFrame, TOOLS};
use sabr_ndi::{HandleReading, HandleStatus, Stamped};

/// The port handle of each tool, in [`Tool`] order (base, front, back, tip).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HandleMap(pub [u8; TOOLS]);

impl Default for HandleMap {
    /// Handles 1-4 = base, front, back, tip: the simulated rig's wiring.
    fn default() -> Self {
        HandleMap([1, 2, 3, 4])
    }
}

impl FromStr for HandleMap {
    type Err = String;

    /// Four hexadecimal port handles separated by commas, e.g. `01,02,03,04` or `0A,0B,0C,0D`.
    fn from_str(text: &str) -> Result<Self, String> {
        let parts: Vec<&str> = text.split(',').map(str::trim).collect();
        if parts.len() != TOOLS {
            return Err(format!(
                "`{text}`: expected {TOOLS} port handles (base,front,back,tip), got {}",
                parts.len()
            ));
        }
        let mut handles = [0u8; TOOLS];
        for (slot, part) in handles.iter_mut().zip(&parts) {
            *slot = match u8::from_str_radix(part, 16) {
                Ok(0) | Err(_) => {
                    return Err(format!(
                        "`{part}` is not a port handle (hexadecimal 01 to FF)"
                    ))
                }
                Ok(handle) => handle,
            };
        }
        for (i, handle) in handles.iter().enumerate() {
            if handles[..i].contains(handle) {
                return Err(format!("`{text}`: port handle {handle:02X} given twice"));
            }
        }
        Ok(HandleMap(handles))
    }
}

impl HandleMap {
    /// The port handle of `tool`.
    pub fn handle(&self, tool: Tool) -> u8 {
        self.0[tool as usize]
    }
}

/// The frame message of a stamped reply: `seq`, the arrival stamp, the estimated time the frame
/// became available at the device, the device's frame number and each tool's reading (a tool
/// whose handle is not in the reply is `Disabled`).
pub fn tracker_frame(seq: u64, stamped: &Stamped, map: &HandleMap) -> TrackerFrame {
    let reply = &stamped.reply;
    TrackerFrame {
        seq,
        arrival_t_ns: stamped.arrival_ns,
        available_t_ns: stamped.available_ns,
        // Stamped by the caller right before its send.
        sent_t_ns: 0,
        frame_number: reply.frame().unwrap_or(0),
        tools: Tool::ALL.map(|tool| tool_sample(tool, reply.handle(map.handle(tool)))),
    }
}

fn tool_sample(tool: Tool, reading: Option<&HandleReading>) -> ToolSample {
    let status_only = |status| ToolSample {
        status,
        ..ToolSample::default()
    };
    let Some(reading) = reading else {
        return status_only(ToolStatus::Disabled);
    };
    match (reading.status, reading.transform) {
        (HandleStatus::Valid, Some(transform)) => ToolSample {
            status: ToolStatus::Ok,
            // The tip sphere is a point: its orientation is meaningless.
            quaternion: if tool == Tool::Tip {
                [1.0, 0.0, 0.0, 0.0]
            } else {
                transform.q.map(f64::from)
            },
            position_mm: transform.t.map(f64::from),
            rms_mm: f64::from(transform.rms),
        },
        (HandleStatus::Disabled | HandleStatus::Unoccupied, _) => status_only(ToolStatus::Disabled),
        _ => status_only(ToolStatus::Missing),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_ndi::{ReplyOptions, TrackingReply, Transform};
    use std::time::Instant;

    fn reading(handle: u8, transform: Option<Transform>, frame: u32) -> HandleReading {
        let status = if transform.is_some() {
            HandleStatus::Valid
        } else {
            HandleStatus::Missing
        };
        HandleReading {
            transform,
            frame: Some(frame),
            port_status: Some(0x31),
            ..HandleReading::bare(handle, status)
        }
    }

    fn stamped(handles: Vec<HandleReading>) -> Stamped {
        Stamped {
            arrival: Instant::now(),
            arrival_ns: 123_456_789,
            available_ns: 122_956_789,
            available_half_width_ns: 500_000,
            reply: TrackingReply {
                options: ReplyOptions::TRANSFORMS,
                handles,
                stray_markers: None,
                system_status: 0,
            },
        }
    }

    const POSE: Transform = Transform {
        q: [0.5, 0.5, -0.5, 0.5],
        t: [10.5, -20.25, -950.0],
        rms: 0.125,
    };

    #[test]
    fn tools_follow_their_handles() {
        let tip = Transform {
            q: [1.0, 0.0, 0.0, 0.0],
            t: [1.0, 2.0, -900.0],
            rms: 0.0,
        };
        let reply = stamped(vec![
            reading(4, Some(tip), 41),
            reading(2, None, 41),
            reading(1, Some(POSE), 42),
        ]);
        let frame = tracker_frame(7, &reply, &HandleMap::default());
        assert_eq!(
            (
                frame.seq,
                frame.arrival_t_ns,
                frame.available_t_ns,
                frame.frame_number
            ),
            (7, 123_456_789, 122_956_789, 42)
        );
        let base = frame.tool(Tool::Base);
        assert_eq!(base.status, ToolStatus::Ok);
        assert_eq!(base.quaternion, [0.5, 0.5, -0.5, 0.5]);
        assert_eq!(base.position_mm, [10.5, -20.25, -950.0]);
        assert_eq!(base.rms_mm, 0.125);
        assert_eq!(frame.tool(Tool::Front).status, ToolStatus::Missing);
        // Handle 3 is not in the reply: not enabled on the device.
        assert_eq!(frame.tool(Tool::Back).status, ToolStatus::Disabled);
        let tip_sample = frame.tool(Tool::Tip);
        assert!(tip_sample.is_ok());
        assert_eq!(tip_sample.position_mm, [1.0, 2.0, -900.0]);
        assert_eq!(tip_sample.quaternion, [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn a_custom_handle_map_reassigns_tools() {
        let map: HandleMap = "0A, 0b,0C,0D".parse().unwrap();
        assert_eq!(map, HandleMap([0x0A, 0x0B, 0x0C, 0x0D]));
        let reply = stamped(vec![
            reading(0x0C, Some(POSE), 9),
            reading(0x01, Some(POSE), 9),
        ]);
        let frame = tracker_frame(1, &reply, &map);
        assert!(frame.tool(Tool::Back).is_ok());
        assert_eq!(frame.tool(Tool::Base).status, ToolStatus::Disabled);
    }

    #[test]
    fn disabled_handles_and_bad_maps() {
        let reply = stamped(vec![HandleReading::bare(1, HandleStatus::Disabled)]);
        let frame = tracker_frame(1, &reply, &HandleMap::default());
        assert_eq!(frame.tool(Tool::Base).status, ToolStatus::Disabled);
        assert_eq!(frame.frame_number, 0);
        for bad in [
            "01,02,03",
            "01,02,03,04,05",
            "01,02,03,zz",
            "00,01,02,03",
            "01,01,02,03",
        ] {
            assert!(bad.parse::<HandleMap>().is_err(), "{bad}");
        }
    }
}

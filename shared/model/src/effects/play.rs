//! Backlash as a play operator: the hysteresis of a transmission with a gap. After the
//! motor reverses, the joint stays put until the motor has crossed the gap; then it follows
//! again, lagging by half the gap. The output depends on the input's history, not only on
//! the sign of its velocity: a short stroke that ends inside the gap leaves the joint where
//! it was.
//!
//! With input `x` (the paper joint angle, rad) and half-width `h`, the output is
//! `y ← clamp(y, x − h, x + h)` applied along the input's path. Between two turning points
//! the input is monotonic, and clamping along a monotonic path equals clamping once at its
//! end, so the output at any instant follows exactly from the turning points of the input
//! ([`PlayMemory`]) and its present value ([`play_output`]). Like every hysteresis of this
//! kind the play forgets a pair of turning points once the input goes beyond the older of
//! them (the wiping-out property), so the memory holds only the nested, shrinking
//! oscillations since the last large stroke.

/// Turning points of one joint that [`PlayMemory`] keeps after wiping out. Older ones
/// matter only when more than this many nested oscillations were each shorter than the gap.
pub const PLAY_MEMORY: usize = 12;

/// The turning points of one joint's input that still matter, in encoder counts
/// (fractional), newest first: alternating maxima and minima, each pair closer together
/// than the pair before it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlayMemory {
    turns: [f64; PLAY_MEMORY],
    len: usize,
    from_rest: bool,
}

impl PlayMemory {
    /// Records a turning point at `counts`. `from_rest` marks the point where the joint
    /// first moved (the gap's state before it is unknown and taken as centred). Once the
    /// memory is full that start is forgotten (the gap taken as closed against the motion
    /// at the oldest point kept); from then on a turning point beyond the previous one of
    /// its kind wipes out that one and the turning point after it. While the start is
    /// remembered nothing is wiped out: a centred gap is no turning point, and a later one
    /// cannot stand for it.
    pub fn push(&mut self, counts: f64, from_rest: bool) {
        while !self.from_rest && self.len >= 2 {
            let (last, previous) = (self.turns[0], self.turns[1]);
            let beyond = if counts > last {
                counts >= previous
            } else {
                counts <= previous
            };
            if !beyond {
                break;
            }
            self.turns.copy_within(2..self.len, 0);
            self.len -= 2;
        }
        self.turns.copy_within(0..PLAY_MEMORY - 1, 1);
        self.turns[0] = counts;
        if self.len == PLAY_MEMORY {
            self.from_rest = false;
        } else {
            self.len += 1;
            if self.len == 1 {
                self.from_rest = from_rest;
            }
        }
    }

    /// The remembered turning points (counts), newest first.
    pub fn turns(&self) -> &[f64] {
        &self.turns[..self.len]
    }

    /// True when the oldest remembered point is where the joint first moved from rest.
    pub fn starts_from_rest(&self) -> bool {
        self.from_rest
    }
}

/// Output (rad) of the play operator of half-width `half_width` (rad) at input `x` (rad),
/// moving in `direction` (±1, 0 when unknown), given the input at the remembered turning
/// points `turns_rad` (rad, newest first). `from_rest`: the oldest turning point is where
/// the input first moved, with the gap centred there.
///
/// Before the oldest remembered turning point the gap is taken as closed against the
/// motion that arrived there (the stroke before it is unknown but, being older than
/// [`PLAY_MEMORY`] turns, almost always longer than the gap).
pub fn play_output(
    half_width: f64,
    x: f64,
    direction: f64,
    turns_rad: &[f64],
    from_rest: bool,
) -> f64 {
    let Some((&oldest, newer)) = turns_rad.split_last() else {
        // No turning point: steady motion in `direction`, or never moved.
        return x - direction * half_width;
    };
    // Direction of the stroke that left the oldest turning point.
    let leaving = match newer.last() {
        Some(&next) => (next - oldest).signum(),
        None => direction,
    };
    let mut y = if from_rest {
        oldest
    } else {
        oldest + leaving * half_width
    };
    for &turn in newer.iter().rev() {
        y = y.clamp(turn - half_width, turn + half_width);
    }
    y.clamp(x - half_width, x + half_width)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_keeps_shrinking_oscillations_and_wipes_out_the_rest() {
        let mut memory = PlayMemory::default();
        memory.push(0.0, true);
        assert!(memory.starts_from_rest());
        // Shrinking oscillations are all kept, newest first.
        for turn in [10.0, 1.0, 9.0, 2.0, 8.0] {
            memory.push(turn, false);
        }
        assert_eq!(memory.turns(), &[8.0, 2.0, 9.0, 1.0, 10.0, 0.0]);
        // While the start is remembered nothing is wiped out: shrinking and growing
        // oscillations alike are kept, until a full memory forgets the start.
        for k in 0..(PLAY_MEMORY - 6) {
            memory.push(if k % 2 == 0 { 0.5 } else { 11.0 }, false);
        }
        assert_eq!(memory.turns().len(), PLAY_MEMORY);
        assert!(memory.starts_from_rest());
        memory.push(0.4, false);
        assert!(!memory.starts_from_rest());
        // Then a maximum beyond the earlier ones wipes out every pair below it.
        memory.push(12.0, false);
        assert_eq!(memory.turns(), &[12.0]);
        // Shrinking oscillations are kept, newest first; a minimum beyond the first wipes
        // them out.
        for turn in [1.0, 10.0, 2.0, 9.0, 3.0] {
            memory.push(turn, false);
        }
        assert_eq!(memory.turns(), &[3.0, 9.0, 2.0, 10.0, 1.0, 12.0]);
        memory.push(8.0, false);
        memory.push(0.5, false);
        assert_eq!(memory.turns(), &[0.5, 12.0]);
    }

    #[test]
    fn after_a_reversal_the_output_stays_until_the_gap_is_crossed() {
        let h = 0.005;
        // Up to 1.0, then back down: turns [1.0, 0.0 (start)].
        let turns = [1.0, 0.0];
        assert!((play_output(h, 0.5, 1.0, &turns[1..], true) - (0.5 - h)).abs() < 1e-15);
        for travel in [0.0, 0.002, 0.006, 0.0099, 0.0101, 0.05] {
            let x = 1.0 - travel;
            let y = play_output(h, x, -1.0, &turns, true);
            let expected = if travel < 2.0 * h { 1.0 - h } else { x + h };
            assert!(
                (y - expected).abs() < 1e-12,
                "travel {travel}: {y} vs {expected}"
            );
        }
    }

    #[test]
    fn matches_the_sample_by_sample_operator_on_random_paths() {
        let h = 0.004;
        let mut state = 12345u64;
        let mut random = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..400 {
            // From rest (fewer strokes than the memory holds), or after a long first stroke
            // that closes the gap (then many strokes, most shorter than the gap, so that the
            // memory wipes out).
            let from_rest = case % 2 == 0;
            let mut direction = if random() < 0.5 { 1.0 } else { -1.0 };
            let mut path = vec![0.0];
            let mut memory = PlayMemory::default();
            let mut reference = 0.0;
            let strokes = if from_rest {
                1 + (random() * (PLAY_MEMORY - 1) as f64) as usize
            } else {
                memory.push(-direction * 0.05, false);
                reference = -direction * h;
                1 + (random() * 60.0) as usize
            };
            for stroke_index in 0..strokes {
                let stroke = random() * if random() < 0.7 { 0.006 } else { 0.03 };
                let last = *path.last().unwrap();
                if stroke_index > 0 || from_rest {
                    memory.push(last, from_rest && stroke_index == 0);
                }
                for k in 1..=20 {
                    let x = last + direction * stroke * k as f64 / 20.0;
                    path.push(x);
                    reference = f64::clamp(reference, x - h, x + h);
                }
                direction = -direction;
            }
            direction = -direction;
            let x = *path.last().unwrap();
            let y = play_output(h, x, direction, memory.turns(), memory.starts_from_rest());
            assert!(
                (y - reference).abs() < 1e-12,
                "case {case}: {y} vs {reference}"
            );
        }
    }
}

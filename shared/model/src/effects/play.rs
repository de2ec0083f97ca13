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
//! ([`PlayMemory`]) and its present value ([`play_output`]).

/// Turning points of one joint that [`PlayMemory`] keeps. Older ones matter only when every
/// stroke between them and now was shorter than the gap.
pub const PLAY_MEMORY: usize = 6;

/// The recent turning points of one joint's input, in encoder counts (fractional), newest
/// first: where its direction of motion last changed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlayMemory {
    turns: [f64; PLAY_MEMORY],
    len: usize,
    from_rest: bool,
}

impl PlayMemory {
    /// Records a turning point at `counts`. `from_rest` marks the point where the joint
    /// first moved (the gap's state before it is unknown and taken as centred).
    pub fn push(&mut self, counts: f64, from_rest: bool) {
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

    /// The play operator run sample by sample.
    fn reference(half_width: f64, path: &[f64], start: f64) -> f64 {
        path.iter()
            .fold(start, |y, &x| y.clamp(x - half_width, x + half_width))
    }

    #[test]
    fn memory_keeps_the_newest_turns_first() {
        let mut memory = PlayMemory::default();
        memory.push(1.0, true);
        assert!(memory.starts_from_rest());
        for k in 2..=(PLAY_MEMORY + 2) {
            memory.push(k as f64, false);
        }
        assert_eq!(memory.turns().len(), PLAY_MEMORY);
        assert_eq!(memory.turns()[0], (PLAY_MEMORY + 2) as f64);
        assert!(!memory.starts_from_rest(), "the start has been forgotten");
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
        for _ in 0..200 {
            // A path of strokes, some shorter than the gap.
            let mut path = vec![0.0];
            let mut turns = vec![0.0];
            let mut direction = if random() < 0.5 { 1.0 } else { -1.0 };
            for _ in 0..(1 + (random() * 8.0) as usize) {
                let stroke = random() * 0.02;
                let last = *path.last().unwrap();
                for k in 1..=20 {
                    path.push(last + direction * stroke * k as f64 / 20.0);
                }
                turns.push(*path.last().unwrap());
                direction = -direction;
            }
            turns.pop();
            direction = -direction;
            let x = *path.last().unwrap();
            let newest_first: Vec<f64> = turns.iter().rev().copied().collect();
            let y = play_output(h, x, direction, &newest_first, true);
            let expected = reference(h, &path, 0.0);
            assert!((y - expected).abs() < 1e-12, "{y} vs {expected}");
        }
    }
}

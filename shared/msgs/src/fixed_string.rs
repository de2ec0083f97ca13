//! A fixed-capacity UTF-8 string that can live in shared memory.

use iceoryx2::prelude::ZeroCopySend;

/// A UTF-8 string of at most `N` bytes stored inline, zero-padded (no heap, `Copy`, `repr(C)`).
///
/// Used for node names, file paths and error texts inside messages.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Hash, ZeroCopySend)]
pub struct FixedString<const N: usize> {
    len: u32,
    bytes: [u8; N],
}

/// Why a text does not fit a [`FixedString`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FixedStringError {
    /// The text is longer than the capacity (both in bytes).
    #[error("text of {len} bytes exceeds the capacity of {capacity} bytes")]
    TooLong {
        /// Length of the rejected text in bytes.
        len: usize,
        /// Capacity of the string type in bytes.
        capacity: usize,
    },
}

impl<const N: usize> FixedString<N> {
    /// Capacity in bytes.
    pub const CAPACITY: usize = N;

    /// The empty string.
    pub const fn empty() -> Self {
        Self {
            len: 0,
            bytes: [0; N],
        }
    }

    /// Copies `text` in; an error if it is longer than `N` bytes (never silently cut).
    pub fn new(text: &str) -> Result<Self, FixedStringError> {
        if text.len() > N {
            return Err(FixedStringError::TooLong {
                len: text.len(),
                capacity: N,
            });
        }
        let mut out = Self::empty();
        out.bytes[..text.len()].copy_from_slice(text.as_bytes());
        out.len = text.len() as u32;
        Ok(out)
    }

    /// Copies in as much of `text` as fits, cutting at a character boundary; for messages whose
    /// text is informative only (error reasons), where a cut text beats no text.
    pub fn truncated(text: &str) -> Self {
        let mut end = text.len().min(N);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        Self::new(&text[..end]).unwrap_or_else(|_| Self::empty())
    }

    /// The stored text. A corrupt length or invalid UTF-8 (only possible if another process
    /// wrote garbage) yields the longest valid prefix.
    pub fn as_str(&self) -> &str {
        let len = (self.len as usize).min(N);
        match std::str::from_utf8(&self.bytes[..len]) {
            Ok(text) => text,
            Err(error) => {
                std::str::from_utf8(&self.bytes[..error.valid_up_to()]).unwrap_or_default()
            }
        }
    }

    /// True if the string holds no text.
    pub fn is_empty(&self) -> bool {
        self.as_str().is_empty()
    }
}

impl<const N: usize> Default for FixedString<N> {
    fn default() -> Self {
        Self::empty()
    }
}

impl<const N: usize> std::fmt::Debug for FixedString<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self.as_str(), f)
    }
}

impl<const N: usize> std::fmt::Display for FixedString<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl<const N: usize> TryFrom<&str> for FixedString<N> {
    type Error = FixedStringError;

    fn try_from(text: &str) -> Result<Self, Self::Error> {
        Self::new(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_text_up_to_capacity() {
        let text: FixedString<8> = FixedString::new("encoder").unwrap();
        assert_eq!(text.as_str(), "encoder");
        assert_eq!(
            FixedString::<8>::new("12345678").unwrap().as_str(),
            "12345678"
        );
        assert!(FixedString::<8>::default().is_empty());
    }

    #[test]
    fn rejects_text_longer_than_capacity() {
        let error = FixedString::<4>::new("12345").unwrap_err();
        assert_eq!(
            error,
            FixedStringError::TooLong {
                len: 5,
                capacity: 4
            }
        );
    }

    #[test]
    fn truncation_respects_character_boundaries() {
        // "é" is two bytes: cutting "aé" to 2 bytes must drop the whole character.
        assert_eq!(FixedString::<2>::truncated("aé").as_str(), "a");
        assert_eq!(FixedString::<3>::truncated("aé").as_str(), "aé");
    }
}

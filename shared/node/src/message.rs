//! The bound every payload of the graph meets, below ports and transports so both can name it.

use iceoryx2::prelude::ZeroCopySend;
use std::fmt::Debug;

/// What a message type must be to travel through the graph: every `sabr_msgs` type is one.
pub trait Message: Debug + ZeroCopySend + Copy + 'static {}
impl<T: Debug + ZeroCopySend + Copy + 'static> Message for T {}

//! The streaming engine: fixed-rate frames of a motion (docs/motion.md; a clip is
//! a one-layer motion) for gRPC server streaming and WebSocket viewers
//! alike (docs/api.md).
//!
//! The flow of a stream: a transport validates a request into
//! [`StreamParams`] (bound to the motion over the pinned clip versions it
//! starts on, `pinned`), takes a [`StreamPermit`] from the [`Engine`] (the stream
//! caps), and asks for a [`Subscription`]. The engine matches it to a
//! playback (`hub`; joinable ones are listed in `registry`
//! until their first tick), which wakes on its schedule (`schedule`: tick `k` due
//! at `start + k/fps` on a grid with a millisecond phase, computed, never
//! accumulated; `ticker` wakes it; late wake-ups skip to the latest tick and
//! count the rest as dropped) — as its own task while it is shared, driven
//! by its viewer when it has only one —, moves its playhead (`playhead`: controls act on the next tick),
//! samples its `anim::motion::Player` once (crossfades and weight ramps live there), collects the events crossed since the previous
//! frame (`events`), encodes once (`encode`: JSON, protobuf or compact frames
//! of the layout `compact` chose) and
//! publishes the bytes to a small broadcast buffer. Each subscription
//! reads from that buffer, turning overwritten frames into its own
//! `dropped` count, and its transport sends the bytes: `grpc` as a
//! response stream of pre-encoded [`WireFrame`]s, `ws` as text or binary
//! messages. What a subscription has sent its client is its `lane`; a
//! broadcast's WebSocket viewer whose socket keeps up parks its lane, and
//! the broadcast's `fanout` writes its frames to the socket directly, a few
//! tasks per encoding rather than one per viewer.
//!
//! A graph stream (docs/graphs.md, `graph`) plays a stored graph in place
//! of the motion player, one graph tick per tick, driven by `set` controls.
//!
//! A broadcast (docs/broadcasts.md, `broadcast`) is a playback made a feature: named,
//! created and deleted explicitly, joinable at any tick, controlled for all
//! its viewers with controls stamped by the tick they apply from.
//!
//! **Architecture invariants.** Nothing here knows about HTTP routes, the
//! store or authentication: transports hand in a motion over pinned clips
//! (and resolve a crossfade's motion for it) and get bytes out. No lock is held across an await. A slow client costs a fixed
//! amount of memory and never delays a playback: publishing never waits.
//! Every task started here ends on shutdown, when its last viewer leaves,
//! or on `stop` (a broadcast: when deleted or idle for its timeout). A playback never changes clip version mid-stream: replacing
//! or deleting a clip affects streams started afterwards only, so no frame
//! is ever a mix of two versions.

mod broadcast;
mod broadcast_budget;
mod broadcast_program;
mod broadcast_reach;
mod checkpoint;
mod compact;
mod control;
mod encode;
mod engine;
mod events;
mod fade_chain;
mod fanout;
mod graph;
pub mod grpc;
mod hub;
mod lane;
mod limits;
mod params;
mod pinned;
mod playhead;
mod producer;
mod registry;
mod schedule;
mod subscription;
mod ticker;
pub mod ws;

pub use broadcast::{
    Broadcast, BroadcastError, BroadcastSpec, BroadcastStatus, Broadcasts, Checkpointing, ControlGate, Held, Journal,
    LayoutWork, STORE_QUEUE, new_control_id,
};
pub use broadcast_budget::{BroadcastCharge, OVERRUN_FACTOR, TICK_ALLOWANCE_UNITS};
pub use broadcast_program::{ControlLog, Program, StampedControl};
pub use broadcast_reach::{MAX_PLAYED, Reach, ReachSig};
pub use checkpoint::{Checkpoint, CheckpointError};
pub use compact::{CompactLayout, CompactRefusal, CompactRequest, RANGE_RATE, range_sample_price, range_source};
pub use control::{
    Control, ControlError, ControlRefusal, Crossfade, LayoutJob, LayoutRun, LayoutRunner, MAX_FADE_SECONDS,
    ParsedControl, Repricing, parse_control,
};
pub use encode::{Encoded, Encoding, FrameData, FrameEncoder, Names};
pub use engine::{Engine, EngineConfig};
pub use events::{MAX_EVENTS_PER_FRAME, crossed};
pub use formats::wire::frame::WireFrame;
pub use graph::{GraphProgram, StreamGraph};
pub use hub::{EndReason, unix_nanos};
pub use lane::{Delivered, Direct, DirectWrite};
pub use limits::{AdmitError, StreamPermit};
pub use params::{MAX_FPS, ParamError, StreamParams, StreamRequest};
pub use pinned::{Pinned, PinnedClip, StreamMotion};
pub use playhead::{MAX_SPEED, Playhead};
pub use schedule::{Grid, MAX_CATCH_UP, Schedule, Tick};
pub use subscription::{Controller, Next, StoreOutcome, Subscription};

pub use formats::wire::grid::PHASE_HEADER;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_broadcast;
#[cfg(test)]
mod tests_broadcast_budget;
#[cfg(test)]
mod tests_checkpoint;
#[cfg(test)]
mod tests_compact;
#[cfg(test)]
mod tests_fanout;
#[cfg(test)]
mod tests_graph;
#[cfg(test)]
mod tests_ws;

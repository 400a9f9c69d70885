//! # rothray-csg: Roth's CSG on interval lists
//!
//! A leaf reports the spans where a ray is inside it ([`rothray_primitives`]);
//! [`spans::combine`] merges two sorted span lists by Table 1 (union,
//! intersection, difference), regularised so coincident faces never speckle.
//! [`program::Program`] holds every CSG tree of a scene as a flat node array and
//! evaluates a ray without recursion, with Roth's early outs:
//!
//! * an intersection stops at its first empty operand;
//! * a difference stops when its positive operand is empty, and clips every
//!   subtrahend to the positive's extent;
//! * children whose bounds miss the ray segment are skipped without evaluation;
//! * wide unions and differences (more than [`program::WIDE_THRESHOLD`] operands)
//!   visit their operands through a BVH (`scenes/cheese` subtracts 1000 spheres);
//! * nearest-hit queries ([`program::Mode::Nearest`]) let unions stop at the
//!   first entry they have confirmed.
#![warn(missing_docs)]

pub mod counts;
pub mod edits;
mod follow;
pub mod program;
pub mod spans;
pub mod spans8;
pub mod tile;
pub mod tile_list;

pub use counts::{take_eval_counts, EvalCounts};
pub use edits::{Edit, EditLog};
pub use follow::FollowCounts;
pub use program::object_packet::{FirstOf, Firsts8, LaneRanges};
pub use program::{
    first_surface, leaf_asks_again, DeepFirst, MemoLanes, Mode, NodeKind, PacketMemo, Program, ProgramBuilder, RayCtx, Scratch,
};
pub use spans::{combine, spill_count, Op, SpanList};
pub use tile::{TileCounts, TileProgram};

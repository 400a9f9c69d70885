//! Integration tests of the whole engine: one binary, modules inside.
//!
//! Every randomized test prints its seed; rerun a failure with the same seed
//! by editing the constant it names.

#[path = "../io/src/assimp_corpus.rs"]
mod assimp_corpus;
mod bad_input;
mod cli;
mod coincident;
#[path = "../io/src/comb_face.rs"]
mod comb_face;
mod csg_oracle;
mod hostile;
mod leaf_oracle;
mod measure;
mod oracle;
mod povray;
mod render_flat;
mod scale_range;
mod split;
mod stress;
mod stress_data;
mod stress_grazing;
mod stress_tangent;
mod tiles;

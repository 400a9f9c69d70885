//! A mesh as a CSG leaf: imports `scenes/bunny.obj` through `rothray_io`,
//! subtracts a sphere from it, and prints the Roth spans along a ray.
//!
//! ```text
//! cargo run --release --example mesh_cut [-- path/to/mesh.obj]
//! ```

use std::{path::PathBuf, sync::Arc};

use glam::Vec3;
use hecs::World;
use rothray::engine::*;
use rothray::io::mesh::load_mesh_data;

fn main() {
    let path =
        std::env::args().nth(1).map(PathBuf::from).unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/bunny.obj"));
    let (mesh, warnings) = load_mesh_data(&path, InsideRule::Orientation).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    for w in &warnings {
        println!("warning: {w}");
    }
    let mesh = Arc::new(mesh);
    let bounds = mesh.local_bounds();
    println!("{}: {} triangles, bounds {:.3} .. {:.3}", path.display(), mesh.triangle_count(), bounds.min, bounds.max);

    // The mesh minus a sphere at its centre, half its size.
    let mut world = World::new();
    let m = world.spawn((MeshSolid(mesh.clone()), Name::new("mesh")));
    let radius = 0.18 * bounds.diagonal_length();
    let s = world.spawn((Sphere { center: bounds.center(), radius }, Name::new("sphere")));
    let cut = world.spawn((CsgNode::difference([m, s]), Name::new("cut")));
    let mut scene = RenderScene::default();
    sync_scene(&mut world, &mut scene).unwrap();

    // A ray along x through the centre: the mesh's spans with the sphere's
    // span taken out.
    let from = Vec3::new(bounds.min.x - 1.0, bounds.center().y, bounds.center().z);
    let ray = Ray::new(from, Vec3::X);
    let name = |s: rothray::primitives::Surf| if s.is_real() { scene.leaf_name(s.leaf_index()).into_owned() } else { "(clipped)".into() };
    let spans = scene.spans_of(&ray, cut);
    println!("ray from {from:.3} along +x: {} span(s) of the cut", spans.len());
    for sp in &spans {
        println!("  [{:.4}, {:.4}]  enters {} , leaves {}", sp.t0, sp.t1, name(sp.s0), name(sp.s1));
    }
    let whole = world.spawn((MeshSolid(mesh),));
    sync_scene(&mut world, &mut scene).unwrap();
    for sp in scene.spans_of(&ray, whole) {
        println!("the whole mesh on the same ray: [{:.4}, {:.4}]", sp.t0, sp.t1);
    }
}

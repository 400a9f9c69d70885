//! Loads a scene and nothing more (no bake, no render), to measure the io side
//! alone: `/usr/bin/time -v target/release/examples/load_only SCENE.json`.

fn main() {
    let Some(p) = std::env::args().nth(1) else {
        eprintln!("usage: load_only SCENE.json");
        std::process::exit(2);
    };
    let t = std::time::Instant::now();
    match rothray_io::load_scene(std::path::Path::new(&p)) {
        Ok(sf) => eprintln!("loaded {} entities in {:?}", sf.world.len(), t.elapsed()),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    }
}

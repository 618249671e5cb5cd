//! The map compiler: a ROS map_server map in, a `.refdb` out, one module per
//! stage. Nothing here uses [`crate::tools`].

pub mod compile;
pub mod connectivity;
pub mod edt;
pub mod error;
pub mod fit;
pub mod gvd;
pub mod index;
pub mod mapfile;
pub mod pipeline;
pub mod reach;
pub mod rng;
pub mod sim;
pub mod sites;
pub mod writer;

#[cfg(test)]
mod tests {
    /// The compiler is the part a robot project builds its maps with; the
    /// tools (evaluation, scan I/O, synthesis, figures) are built around it.
    /// Keep the dependency one way: no file of the compiler names the tools.
    #[test]
    fn the_compiler_never_uses_the_tools() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/compiler");
        let mut stack = vec![root];
        // Spelled in two parts so that this file does not match itself.
        let needle = concat!("tools", "::");
        let mut seen = 0;
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).expect("read src/compiler") {
                let path = entry.expect("directory entry").path();
                if path.is_dir() {
                    stack.push(path);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    let text = std::fs::read_to_string(&path).expect("read source");
                    for (n, line) in text.lines().enumerate() {
                        let code = line.split("//").next().unwrap_or("");
                        assert!(
                            !code.contains(needle),
                            "{}:{} uses the tools: {line}",
                            path.display(),
                            n + 1
                        );
                    }
                    seen += 1;
                }
            }
        }
        assert!(seen >= 11, "only {seen} compiler sources found");
    }
}

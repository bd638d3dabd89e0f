//! The README's list of what the loader reads is derived from the loader's table: every plugin
//! the table dispatches to must be named there, so the documentation cannot fall behind.

use fireflies::render::mitsuba::table::{BSDFS, EMITTERS, SHAPES, TEXTURES, names};

#[test]
fn the_readme_names_every_plugin_of_the_table() {
    let readme = include_str!("../README.md");
    let start = readme
        .find("**What the loader reads**")
        .expect("the loader section");
    let section = &readme[start..];
    let end = section
        .find("\n\n**The integrator**")
        .unwrap_or(section.len());
    let section = &section[..end];
    let mut all = names(BSDFS);
    all.extend(names(TEXTURES));
    all.extend(names(EMITTERS));
    all.extend(names(SHAPES));
    all.push("area");
    for name in all {
        assert!(
            section.contains(&format!("`{name}`")),
            "the README's loader section does not name `{name}`"
        );
    }
}

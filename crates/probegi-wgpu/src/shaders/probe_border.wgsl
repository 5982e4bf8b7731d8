// Guard borders of octahedral tiles (probegi_core::probe_border), shared by the
// passes that write tiles: the DDGI blend and the shadowing field's blend.

// probegi_core::probe_border::update_tile_border: border texel (x, y) of a tile
// with `n` interior texels copies its mirrored interior source.
fn border_source(x: u32, y: u32, n: u32) -> vec2<u32> {
    let last = n + 1u;
    if ((x == 0u || x == last) && (y == 0u || y == last)) {
        // Corners take the diagonally opposite interior corner.
        return vec2<u32>(select(1u, n, x == 0u), select(1u, n, y == 0u));
    }
    if (y == 0u) { return vec2<u32>(n + 1u - x, 1u); }
    if (y == last) { return vec2<u32>(n + 1u - x, n); }
    if (x == 0u) { return vec2<u32>(1u, n + 1u - y); }
    return vec2<u32>(n, n + 1u - y);
}

fn is_border(x: u32, y: u32, n: u32) -> bool {
    return x == 0u || y == 0u || x == n + 1u || y == n + 1u;
}


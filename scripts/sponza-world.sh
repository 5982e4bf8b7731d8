# Sourced by scripts/world-scale.sh, world-static.sh and world-flythrough.sh:
# `sponza_world N` prints the scene TOML of N×N side-by-side copies of the
# shared Dabrovic Sponza, 35 m × 16 m apart, under a sun and a sky (no camera).
sponza_world() {
  echo "# $1×$1 copies of Dabrovic Sponza (CC BY-NC, © 2002 Marko Dabrovic; ../shared/scenes), 35 m × 16 m apart."
  echo 'sky_radiance = [0.15, 0.18, 0.25]'
  local i j
  for ((i = 0; i < $1; i++)); do for ((j = 0; j < $1; j++)); do
    printf '[[meshes]]\npath = "shared:scenes/dabrovic-sponza/sponza.obj"\ntranslation = [%s, 0.0, %s]\n' $((i * 35)) $((j * 16))
  done; done
  printf '[[lights]]\nkind = "directional"\ndirection = [0.25, -1.0, 0.15]\ncolor = [1.0, 0.92, 0.8]\nintensity = 12.0\n'
}

/*
 * tileworld bake: a rectangle of cells of any tileset or provider written as
 * a 3D Tiles 1.1 tileset with implicit tiling (a QUADTREE over the cells),
 * for any 3D Tiles client or static server (README "Beyond one machine"):
 *   DIR/tileset.json                    the root: transform, box, templates
 *   DIR/content/{level}/{x}/{y}.glb     a cell's geometry (the finest level)
 *   DIR/subtrees/{level}/{x}/{y}.subtree  availability, from what is on disk
 *   DIR/bake.json                       what was baked (a rerun must match)
 * Each file is written whole (a temporary, then a rename); a rerun skips
 * the cells whose .glb exists; --shard K/N bakes a disjoint part; --finish
 * writes the subtrees and tileset.json from what exists.
 */
#ifndef TW_TOOLS_BAKE_H
#define TW_TOOLS_BAKE_H

/* Runs `tileworld bake ARGS`: argv[0] is "bake". Returns the exit status:
 * 0, 1 (a failure: memory, a file, a cell that cannot be made) or 2 (bad
 * input, one line on stderr). */
int tw_bake_main(int argc, char **argv);

#endif

/* Fuzz target for the reader of tileworld bake's binary glTF tiles
 * (tilesets/tiles3d-glb.c), which the 3D Tiles provider applies to the bytes
 * it fetches: LLVMFuzzerTestOneInput reads the input into a fresh tileset of
 * an 80 x 80 m footprint with one prototype, as the provider does (the root's
 * translation dropped), and, when it reads, finishes the tileset as the
 * provider's tiles are (nothing merged again, clusters of 2048 triangles);
 * then once more moved by a shift, as the bake reads its finer level back.
 * The reason of a failure must be one line. Built with libFuzzer when
 * TW_LIBFUZZER is defined; otherwise a plain main replays the files and
 * folders given as arguments (the seed corpus is tests/corpus/glb3d). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/tilesets-private.h"
#include "tileworld/tiles.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void read_tile(const uint8_t *data, size_t size, const double *shift)
{
    struct tw_tileset *ts = NULL;
    char why[512];
    if (tw_tileset_create("fuzz", 80.0f, 80.0f, &ts) != 0)
        abort();
    if (tw_tileset_add_prototype(ts, "0,0", 1.0f) != 0)
        abort();
    double error = -1.0;
    const int rc = tw_tiles3d_glb_read(data, size, ts, 0, shift, &error, why, sizeof(why));
    if (rc < 0 && (!why[0] || strchr(why, '\n')))
        abort();
    if (rc > 0 || (rc == TW_OK && error == -1.0))
        abort();
    double alone = -1.0;
    if (rc == TW_OK && (tw_tiles3d_glb_error(data, size, &alone) != TW_OK ||
                        !(alone == error || (alone != alone && error != error))))
        abort();
    if (rc == TW_OK) {
        ts->merge_triangles = 1;
        tw_tileset_finish(ts, 2048);
    }
    tw_tileset_destroy(ts);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const double shift[3] = {-40.0, 0.5, 120.0};
    read_tile(data, size, NULL);
    read_tile(data, size, shift);
    return 0;
}

#ifndef TW_LIBFUZZER
#include "tests/fuzz-driver.h"

int main(int argc, char **argv)
{
    struct fuzz_driver d = {.target = "fuzz-glb3d"};
    return fuzz_driver_main(argc, argv, &d);
}
#endif

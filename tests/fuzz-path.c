/* Fuzz target for the camera-path CSV reader (runtime/paths.c):
 * LLVMFuzzerTestOneInput parses the input as a path file on two footprints
 * and, when it loads, moves it by a few cells and checks what every reader of
 * a path relies on. Built with libFuzzer when TW_LIBFUZZER is defined;
 * otherwise a plain main replays the files and folders given as arguments
 * (the seed corpus is tests/corpus/path). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/runtime.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const float footprints[2][2] = {{80.0f, 80.0f}, {0.01f, 3e4f}};
    for (int k = 0; k < 2; k++) {
        struct tw_path p;
        char err[512];
        const float w = footprints[k][0], d = footprints[k][1];
        const int rc = tw_path_parse_csv((const char *)data, size, "fuzz.csv", 0, w, d, &p, err,
                                         sizeof(err));
        if (rc) {
            /* One line, naming the file. */
            if (strncmp(err, "fuzz.csv", 8) != 0 || strchr(err, '\n'))
                abort();
            continue;
        }
        for (uint32_t f = 0; f < p.count; f++) {
            const struct tw_camera *c = &p.keys[f];
            if (!(c->pos.local[0] >= 0.0f && c->pos.local[0] < w && c->pos.local[2] >= 0.0f &&
                  c->pos.local[2] < d) ||
                !isfinite(c->pos.local[1]) || !(fabsf(c->yaw) < 360.0f) ||
                !(fabsf(c->pitch) < 89.9f))
                abort();
        }
        tw_path_translate(&p, -3, INT64_MAX);
        tw_path_finish(&p);
    }
    return 0;
}

#ifndef TW_LIBFUZZER
#include "tests/fuzz-driver.h"

int main(int argc, char **argv)
{
    struct fuzz_driver d = {.target = "fuzz-path"};
    return fuzz_driver_main(argc, argv, &d);
}
#endif

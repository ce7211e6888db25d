/* Fuzz target for the camera-path CSV reader (runtime/paths.c):
 * LLVMFuzzerTestOneInput parses the input as a path file on two footprints
 * and, when it loads, moves it by a few cells and checks what every reader of
 * a path relies on. It also writes the input to a file and loads that (the
 * reader of files works a block at a time): both must give the same path or
 * the same message. Built with libFuzzer when TW_LIBFUZZER is defined;
 * otherwise a plain main replays the files and folders given as arguments
 * (the seed corpus is tests/corpus/path). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "runtime/runtime-internal.h"
#include "tileworld/runtime.h"

/* The input as a file, the same for every input (made on first use). */
static const char *as_file(const uint8_t *data, size_t size)
{
    static char path[64];
    static int fd = -1;
    if (fd < 0) {
        snprintf(path, sizeof(path), "/tmp/tw-fuzz-path-XXXXXX");
        fd = mkstemp(path);
        if (fd < 0)
            abort();
    }
    if (ftruncate(fd, 0) != 0 || (size && pwrite(fd, data, size, 0) != (ssize_t)size))
        abort();
    return path;
}

/* Loading the input from a file gives what parsing it from memory gave. */
static void same_from_file(const uint8_t *data, size_t size, uint32_t frames, float w, float d)
{
    const char *path = as_file(data, size);
    struct tw_path from_memory, from_file;
    char err_memory[512], err_file[512];
    const int rc_memory = tw_path_parse_csv((const char *)data, size, path, frames, w, d,
                                            &from_memory, err_memory, sizeof(err_memory));
    const int rc_file = tw_path_load_csv(path, frames, w, d, &from_file, err_file,
                                         sizeof(err_file));
    if (rc_memory != rc_file || from_memory.count != from_file.count ||
        (rc_memory && strcmp(err_memory, err_file) != 0))
        abort();
    for (uint32_t k = 0; k < from_memory.count; k++) {
        const struct tw_camera *a = &from_memory.keys[k], *b = &from_file.keys[k];
        if (a->pos.cell.i != b->pos.cell.i || a->pos.cell.j != b->pos.cell.j ||
            memcmp(a->pos.local, b->pos.local, sizeof(a->pos.local)) != 0 || a->yaw != b->yaw ||
            a->pitch != b->pitch)
            abort();
    }
    tw_path_finish(&from_memory);
    tw_path_finish(&from_file);
}

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
    same_from_file(data, size, 0, 80.0f, 80.0f);
    same_from_file(data, size, 2, 80.0f, 80.0f);
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

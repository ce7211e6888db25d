/*
 * The library's wall clock for timings (bvh builds, cull frames, renderer
 * and stream statistics): monotonic milliseconds, shared by every module
 * above tiles/. Private to the library: not installed, not public API.
 */
#ifndef TW_TILES_CLOCK_H
#define TW_TILES_CLOCK_H

#include <time.h>

/* Monotonic time in milliseconds (CLOCK_MONOTONIC): only differences mean
 * anything. */
static inline double tw_clock_monotonic_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

#endif

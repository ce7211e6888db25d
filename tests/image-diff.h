/*
 * Comparing the RGB images (3 bytes a pixel) that the GL tests read back.
 */
#ifndef TW_TESTS_IMAGE_DIFF_H
#define TW_TESTS_IMAGE_DIFF_H

#include <stdint.h>
#include <string.h>

/* How many of the pixels of two images of pixels pixels differ. */
static uint32_t count_differing(const uint8_t *a, const uint8_t *b, uint32_t pixels)
{
    uint32_t n = 0;
    for (uint32_t k = 0; k < pixels; k++)
        n += memcmp(a + 3 * k, b + 3 * k, 3) != 0;
    return n;
}

#endif

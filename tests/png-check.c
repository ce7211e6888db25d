/*
 * png-check FILE [OTHER]: decodes FILE with libpng and prints
 *   "size WxH colours N stddev S"
 * (distinct RGB colours, standard deviation of luma in 0-255); with OTHER,
 * an image of the same size, also " differ F" (the fraction of pixels whose
 * colours differ by more than 8 in some channel), " pixels_differ N" (those
 * that differ at all) and " max_diff D" (the largest channel difference).
 * Exit status 1 when a file
 * is not a valid PNG or the sizes differ. test-view.sh judges the figures:
 * a screenshot must decode, and must not be one flat colour.
 */
#include <png.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint8_t *load(const char *file, uint32_t *w, uint32_t *h)
{
    png_image img;
    memset(&img, 0, sizeof(img));
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, file)) {
        fprintf(stderr, "png-check: %s: %s\n", file, img.message);
        return NULL;
    }
    img.format = PNG_FORMAT_RGB;
    uint8_t *rgb = malloc(PNG_IMAGE_SIZE(img));
    if (!rgb || !png_image_finish_read(&img, NULL, rgb, 0, NULL)) {
        fprintf(stderr, "png-check: %s: %s\n", file, rgb ? img.message : "out of memory");
        free(rgb);
        png_image_free(&img);
        return NULL;
    }
    *w = img.width;
    *h = img.height;
    return rgb;
}

int main(int argc, char **argv)
{
    if (argc < 2 || argc > 3) {
        fprintf(stderr, "usage: png-check FILE.png [OTHER.png]\n");
        return 2;
    }
    uint32_t w = 0, h = 0;
    uint8_t *a = load(argv[1], &w, &h);
    if (!a)
        return 1;
    const size_t n = (size_t)w * h;
    uint8_t *seen = calloc(1u << 21, 1);   /* one bit per 24-bit colour */
    if (!seen)
        return 1;
    size_t colours = 0;
    double sum = 0.0, sum2 = 0.0;
    for (size_t k = 0; k < n; k++) {
        const uint8_t *p = a + 3 * k;
        const uint32_t c = (uint32_t)p[0] << 16 | (uint32_t)p[1] << 8 | p[2];
        if (!(seen[c >> 3] & (1u << (c & 7)))) {
            seen[c >> 3] |= (uint8_t)(1u << (c & 7));
            colours++;
        }
        const double y = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
        sum += y;
        sum2 += y * y;
    }
    const double mean = n ? sum / (double)n : 0.0;
    const double var = n ? sum2 / (double)n - mean * mean : 0.0;
    printf("size %ux%u colours %zu stddev %.2f", w, h, colours, sqrt(var > 0.0 ? var : 0.0));
    int rc = 0;
    if (argc == 3) {
        uint32_t w2 = 0, h2 = 0;
        uint8_t *b = load(argv[2], &w2, &h2);
        if (!b || w2 != w || h2 != h) {
            if (b)
                fprintf(stderr, "png-check: %s is %ux%u, %s is %ux%u\n", argv[1], w, h, argv[2],
                        w2, h2);
            rc = 1;
        } else {
            size_t differ = 0, differ_any = 0;
            int max_diff = 0;
            for (size_t k = 0; k < n; k++) {
                int most = 0;
                for (int c = 0; c < 3; c++) {
                    const int d = abs((int)a[3 * k + c] - (int)b[3 * k + c]);
                    most = d > most ? d : most;
                }
                differ += most > 8;
                differ_any += most > 0;
                max_diff = most > max_diff ? most : max_diff;
            }
            printf(" differ %.4f pixels_differ %zu max_diff %d", n ? (double)differ / (double)n : 0.0,
                   differ_any, max_diff);
        }
        free(b);
    }
    printf("\n");
    free(seen);
    free(a);
    return rc;
}

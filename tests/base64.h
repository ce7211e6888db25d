/*
 * Base64 (RFC 4648, with padding), for the data: URIs of the glTF documents
 * that the tests build in memory.
 */
#ifndef TW_TESTS_BASE64_H
#define TW_TESTS_BASE64_H

#include <stddef.h>
#include <stdint.h>

/* Writes the n bytes of data to out as base64 and a NUL: 4 * ceil(n / 3) + 1
 * characters. */
static void base64(const uint8_t *data, size_t n, char *out)
{
    static const char abc[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t o = 0;
    for (size_t k = 0; k < n; k += 3) {
        const uint32_t v = (uint32_t)data[k] << 16 | (k + 1 < n ? (uint32_t)data[k + 1] << 8 : 0) |
                           (k + 2 < n ? data[k + 2] : 0);
        out[o++] = abc[v >> 18 & 63];
        out[o++] = abc[v >> 12 & 63];
        out[o++] = k + 1 < n ? abc[v >> 6 & 63] : '=';
        out[o++] = k + 2 < n ? abc[v & 63] : '=';
    }
    out[o] = '\0';
}

#endif

/* glTF import, buffer views and accessors (gltf-private.h): every byte
 * range checked against its view and buffer with overflow-safe arithmetic,
 * sparse indices in order; accessor data read as floats or indices. */
#include <math.h>
#include <string.h>

#include "tilesets/gltf-private.h"

uint32_t tw_gltf_component_size(int32_t comp)
{
    switch (comp) {
    case TW_GLTF_COMP_BYTE:
    case TW_GLTF_COMP_UNSIGNED_BYTE:
        return 1;
    case TW_GLTF_COMP_SHORT:
    case TW_GLTF_COMP_UNSIGNED_SHORT:
        return 2;
    case TW_GLTF_COMP_UNSIGNED_INT:
    case TW_GLTF_COMP_FLOAT:
        return 4;
    default:
        return 0;
    }
}

static uint32_t type_components(int32_t type)
{
    switch (type) {
    case TW_GLTF_TYPE_SCALAR:
        return 1;
    case TW_GLTF_TYPE_VEC2:
        return 2;
    case TW_GLTF_TYPE_VEC3:
        return 3;
    case TW_GLTF_TYPE_VEC4:
    case TW_GLTF_TYPE_MAT2:
        return 4;
    case TW_GLTF_TYPE_MAT3:
        return 9;
    case TW_GLTF_TYPE_MAT4:
        return 16;
    default:
        return 0;
    }
}

const char *tw_gltf_type_name(int32_t type)
{
    switch (type) {
    case TW_GLTF_TYPE_SCALAR: return "SCALAR";
    case TW_GLTF_TYPE_VEC2: return "VEC2";
    case TW_GLTF_TYPE_VEC3: return "VEC3";
    case TW_GLTF_TYPE_VEC4: return "VEC4";
    case TW_GLTF_TYPE_MAT2: return "MAT2";
    case TW_GLTF_TYPE_MAT3: return "MAT3";
    case TW_GLTF_TYPE_MAT4: return "MAT4";
    default: return "an unknown type";
    }
}

const char *tw_gltf_component_name(int32_t comp)
{
    switch (comp) {
    case TW_GLTF_COMP_BYTE: return "BYTE";
    case TW_GLTF_COMP_UNSIGNED_BYTE: return "UNSIGNED_BYTE";
    case TW_GLTF_COMP_SHORT: return "SHORT";
    case TW_GLTF_COMP_UNSIGNED_SHORT: return "UNSIGNED_SHORT";
    case TW_GLTF_COMP_UNSIGNED_INT: return "UNSIGNED_INT";
    case TW_GLTF_COMP_FLOAT: return "FLOAT";
    default: return "an unknown component type";
    }
}

/* Bytes of one element; 0 if the type or component type is invalid. Matrix
 * columns are padded to 4 bytes (glTF 2.0 §3.6.2.4). */
static uint64_t element_size(int32_t comp, int32_t type)
{
    const uint64_t cs = tw_gltf_component_size(comp), nc = type_components(type);
    if (!cs || !nc)
        return 0;
    if (type == TW_GLTF_TYPE_MAT2 && cs == 1)
        return 8;
    if (type == TW_GLTF_TYPE_MAT3 && cs == 1)
        return 12;
    if (type == TW_GLTF_TYPE_MAT3 && cs == 2)
        return 24;
    return cs * nc;
}

static uint64_t view_stride(const struct tw_gltf_doc_buffer_view *v, uint64_t elem)
{
    return v->byte_stride ? v->byte_stride : elem;
}

/* Checks that [offset, offset + stride * (count - 1) + elem) lies within a
 * view of view_length bytes, without overflow. count >= 1. */
static bool range_fits(uint64_t offset, uint64_t stride, uint64_t count, uint64_t elem,
                       uint64_t view_length)
{
    if (offset > view_length || elem > view_length - offset)
        return false;
    const uint64_t room = view_length - offset - elem;
    return count - 1 == 0 || stride == 0 || (count - 1) <= room / stride;
}

int tw_gltf_check_buffer_views(struct tw_gltf_importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->buffer_view_count; k++) {
        const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[k];
        if (v->buffer < 0 || (uint32_t)v->buffer >= d->buffer_count)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "bufferViews[%u].buffer: %d is not a buffer (%u)", k, v->buffer,
                                d->buffer_count);
        const uint64_t size = d->buffers[v->buffer].size;
        if (v->byte_offset > size || v->byte_length > size - v->byte_offset)
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "bufferViews[%u]: bytes [%llu, %llu + %llu) overrun buffers[%d] "
                "(%llu bytes)",
                k, (unsigned long long)v->byte_offset, (unsigned long long)v->byte_offset,
                (unsigned long long)v->byte_length, v->buffer, (unsigned long long)size);
    }
    return TW_OK;
}

/* Charges the checks' reading of n more bytes of accessor data to what the
 * input allows: overlapping accessors could otherwise make a buffer be
 * read again for each (CHECK_BASE + CHECK_PER_BYTE bytes per byte of the
 * file and its buffers). */
#define CHECK_BASE (64ull << 20)
#define CHECK_PER_BYTE 4ull

int tw_gltf_charge_check(struct tw_gltf_importer *im, int32_t acc, uint64_t n)
{
    const uint64_t allowed = CHECK_BASE + CHECK_PER_BYTE * im->bytes_read;
    im->checked_bytes += n;
    if (im->checked_bytes <= allowed)
        return TW_OK;
    char a[32], b[32];
    return tw_gltf_fail(im, TW_ERR_LIMIT,
                        "accessors[%d]: the meshes' accessors hold %s to check, more than the %s "
                        "allowed for %llu bytes of file and buffers (64 MiB + 4 bytes per byte): "
                        "accessors overlap",
                        acc, tw_gltf_byte_size(im->checked_bytes, a, sizeof(a)),
                        tw_gltf_byte_size(allowed, b, sizeof(b)),
                        (unsigned long long)im->bytes_read);
}

int tw_gltf_check_accessors(struct tw_gltf_importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->accessor_count; k++) {
        const struct tw_gltf_doc_accessor *a = &d->accessors[k];
        const uint64_t elem = element_size(a->component_type, a->type);
        if (!tw_gltf_component_size(a->component_type))
            return tw_gltf_fail(im, TW_ERR_FORMAT, "accessors[%u].componentType: %d is not valid",
                                k, a->component_type);
        if (!elem)
            return tw_gltf_fail(im, TW_ERR_FORMAT, "accessors[%u].type is not valid", k);
        if (a->count < 1 || a->count > UINT32_MAX)
            return tw_gltf_fail(im, TW_ERR_FORMAT, "accessors[%u].count: %llu is not in [1, 2^32)",
                                k, (unsigned long long)a->count);
        if (a->buffer_view >= 0) {
            if ((uint32_t)a->buffer_view >= d->buffer_view_count)
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "accessors[%u].bufferView: %d is not a buffer view (%u)", k,
                                    a->buffer_view, d->buffer_view_count);
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[a->buffer_view];
            const uint64_t stride = view_stride(v, elem);
            if (stride < elem)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u]: bufferViews[%d].byteStride %llu is smaller than "
                    "one element (%llu bytes)",
                    k, a->buffer_view, (unsigned long long)stride, (unsigned long long)elem);
            /* glTF 2.0 §3.6.2.4: data aligned to its component size. */
            const uint32_t cs = tw_gltf_component_size(a->component_type);
            if (a->byte_offset % cs != 0 || (v->byte_offset + a->byte_offset) % cs != 0)
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "accessors[%u].byteOffset: %llu puts its data at byte %llu of "
                                    "buffers[%d], not a multiple of %u (its component type, %s, is "
                                    "aligned to its size)",
                                    k, (unsigned long long)a->byte_offset,
                                    (unsigned long long)(v->byte_offset + a->byte_offset),
                                    v->buffer, cs, tw_gltf_component_name(a->component_type));
            if (!range_fits(a->byte_offset, stride, a->count, elem, v->byte_length))
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u]: %llu elements of %llu bytes every %llu bytes from "
                    "byte %llu overrun bufferViews[%d] (%llu bytes)",
                    k, (unsigned long long)a->count, (unsigned long long)elem,
                    (unsigned long long)stride, (unsigned long long)a->byte_offset, a->buffer_view,
                    (unsigned long long)v->byte_length);
        } else if (a->buffer_view != -1) {
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "accessors[%u].bufferView: %d is not a buffer view", k,
                                a->buffer_view);
        }
        if (!a->sparse)
            continue;
        if (a->sparse_count < 1 || (uint64_t)a->sparse_count > a->count)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "accessors[%u].sparse.count: %d is not in [1, %llu]", k,
                                a->sparse_count, (unsigned long long)a->count);
        const int32_t ic = a->sparse_indices_component_type;
        if (ic != TW_GLTF_COMP_UNSIGNED_BYTE && ic != TW_GLTF_COMP_UNSIGNED_SHORT &&
            ic != TW_GLTF_COMP_UNSIGNED_INT)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "accessors[%u].sparse.indices.componentType: %d is not an unsigned "
                                "integer type",
                                k, ic);
        const struct {
            const char *what;
            int32_t view;
            int32_t offset;
            uint64_t elem;
        } parts[2] = {
            {"indices", a->sparse_indices_view, a->sparse_indices_offset,
             tw_gltf_component_size(ic)},
            {"values", a->sparse_values_view, a->sparse_values_offset, elem},
        };
        for (int p = 0; p < 2; p++) {
            if (parts[p].view < 0 || (uint32_t)parts[p].view >= d->buffer_view_count)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u].sparse.%s.bufferView: %d is not a buffer view (%u)", k,
                    parts[p].what, parts[p].view, d->buffer_view_count);
            if (parts[p].offset < 0)
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "accessors[%u].sparse.%s.byteOffset is negative", k,
                                    parts[p].what);
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[parts[p].view];
            if (!range_fits((uint64_t)parts[p].offset, parts[p].elem, (uint64_t)a->sparse_count,
                            parts[p].elem, v->byte_length))
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "accessors[%u].sparse.%s: %d elements from byte %d overrun "
                                    "bufferViews[%d] (%llu bytes)",
                                    k, parts[p].what, a->sparse_count, parts[p].offset,
                                    parts[p].view, (unsigned long long)v->byte_length);
            const uint32_t cs = tw_gltf_component_size(p == 0 ? ic : a->component_type);
            if ((v->byte_offset + (uint64_t)parts[p].offset) % cs != 0)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u].sparse.%s.byteOffset: %d puts its data at byte %llu "
                    "of buffers[%d], not a multiple of %u (its component size)",
                    k, parts[p].what, parts[p].offset,
                    (unsigned long long)(v->byte_offset + (uint64_t)parts[p].offset), v->buffer,
                    cs);
        }
        /* The spec: sparse indices strictly increase (and so stay below
         * count, checked as they are read too). */
        const uint8_t *idx = tw_gltf_view_data(d, a->sparse_indices_view, a->sparse_indices_offset);
        const uint64_t is = tw_gltf_component_size(ic);
        int err = tw_gltf_charge_check(im, (int32_t)k, is * (uint64_t)a->sparse_count);
        if (err)
            return err;
        for (uint32_t e = 0; e < (uint32_t)a->sparse_count; e++) {
            const uint32_t target = tw_gltf_load_uint(idx + e * is, ic);
            const uint32_t before = e ? tw_gltf_load_uint(idx + (e - 1) * is, ic) : 0;
            if (target >= a->count)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u].sparse.indices[%u]: %u is not below the count %llu", k, e,
                    target, (unsigned long long)a->count);
            if (e > 0 && target <= before)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "accessors[%u].sparse.indices[%u]: %u follows %u; sparse indices "
                    "must strictly increase",
                    k, e, target, before);
        }
    }
    return TW_OK;
}

uint32_t tw_gltf_load_uint(const uint8_t *p, int32_t comp)
{
    switch (comp) {
    case TW_GLTF_COMP_UNSIGNED_BYTE:
        return p[0];
    case TW_GLTF_COMP_UNSIGNED_SHORT:
        return (uint32_t)p[0] | (uint32_t)p[1] << 8;
    default: return tw_gltf_le32(p);
    }
}

float tw_gltf_load_float(const uint8_t *p)
{
    const uint32_t bits = tw_gltf_le32(p);
    float f;
    memcpy(&f, &bits, sizeof(f));
    return f;
}

/* One component as a float: normalized integers map to [0, 1] or [-1, 1]
 * (glTF 2.0 §3.11), other integers keep their value (KHR_mesh_quantization:
 * the node's transform dequantises them). */
static float load_as_float(const uint8_t *p, int32_t comp, bool normalized)
{
    switch (comp) {
    case TW_GLTF_COMP_FLOAT: return tw_gltf_load_float(p);
    case TW_GLTF_COMP_UNSIGNED_BYTE:
        return normalized ? (float)p[0] / 255.0f : (float)p[0];
    case TW_GLTF_COMP_UNSIGNED_SHORT: {
        const uint32_t v = tw_gltf_load_uint(p, comp);
        return normalized ? (float)v / 65535.0f : (float)v;
    }
    case TW_GLTF_COMP_BYTE: {
        const int v = (int)p[0] - (p[0] > 127 ? 256 : 0);
        return normalized ? fmaxf((float)v / 127.0f, -1.0f) : (float)v;
    }
    case TW_GLTF_COMP_SHORT: {
        const int32_t u = (int32_t)tw_gltf_load_uint(p, TW_GLTF_COMP_UNSIGNED_SHORT);
        const int32_t v = u - (u > 32767 ? 65536 : 0);
        return normalized ? fmaxf((float)v / 32767.0f, -1.0f) : (float)v;
    }
    case TW_GLTF_COMP_UNSIGNED_INT:
        return normalized ? (float)((double)tw_gltf_le32(p) / 4294967295.0)
                          : (float)tw_gltf_le32(p);
    default:
        return 0.0f;
    }
}

/* Start of the accessor's data in its buffer, or NULL when it has no buffer
 * view (zeros). The accessor has been checked. */
const uint8_t *tw_gltf_accessor_base(const struct tw_gltf_doc *d,
                                     const struct tw_gltf_doc_accessor *a, uint64_t *stride)
{
    const uint64_t elem = element_size(a->component_type, a->type);
    *stride = elem;
    if (a->buffer_view < 0)
        return NULL;
    const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[a->buffer_view];
    *stride = view_stride(v, elem);
    return d->buffers[v->buffer].data + v->byte_offset + a->byte_offset;
}

const uint8_t *tw_gltf_view_data(const struct tw_gltf_doc *d, int32_t view, int32_t offset)
{
    const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[view];
    return d->buffers[v->buffer].data + v->byte_offset + (uint64_t)offset;
}

/* Applies sparse substitutions: for each entry, copy(out, target, source). */
static int apply_sparse(struct tw_gltf_importer *im, uint32_t index,
                        void (*copy)(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                                     uint32_t n),
                        void *out, uint32_t n)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_accessor *a = &d->accessors[index];
    if (!a->sparse)
        return TW_OK;
    const int32_t ic = a->sparse_indices_component_type;
    const uint64_t is = tw_gltf_component_size(ic);
    const uint64_t elem = element_size(a->component_type, a->type);
    const uint8_t *idx = tw_gltf_view_data(d, a->sparse_indices_view, a->sparse_indices_offset);
    const uint8_t *val = tw_gltf_view_data(d, a->sparse_values_view, a->sparse_values_offset);
    for (uint32_t s = 0; s < (uint32_t)a->sparse_count; s++) {
        const uint32_t target = tw_gltf_load_uint(idx + s * is, ic);
        if (target >= a->count)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "accessors[%u].sparse.indices[%u]: %u is not below the count %llu",
                                index, s, target, (unsigned long long)a->count);
        copy(out, target, val + s * elem, a->component_type, n);
    }
    return TW_OK;
}

static void copy_unnormalized(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                              uint32_t n)
{
    float *f = (float *)out + (size_t)target * n;
    for (uint32_t c = 0; c < n; c++)
        f[c] = load_as_float(src + tw_gltf_component_size(comp) * c, comp, false);
}

static void copy_normalized(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                            uint32_t n)
{
    float *f = (float *)out + (size_t)target * n;
    for (uint32_t c = 0; c < n; c++)
        f[c] = load_as_float(src + tw_gltf_component_size(comp) * c, comp, true);
}

static void copy_uint(void *out, uint32_t target, const uint8_t *src, int32_t comp, uint32_t n)
{
    ((uint32_t *)out)[target] = tw_gltf_load_uint(src, comp);
}

/* Reads the first n components of a checked accessor as floats (integers
 * normalised if the accessor says so, load_as_float()) into out (count * n). */
int tw_gltf_read_floats(struct tw_gltf_importer *im, uint32_t index, uint32_t n, float *out)
{
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[index];
    uint64_t stride;
    const uint8_t *base = tw_gltf_accessor_base(im->doc, a, &stride);
    const uint32_t cs = tw_gltf_component_size(a->component_type);
    for (uint64_t k = 0; k < a->count; k++)
        for (uint32_t c = 0; c < n; c++)
            out[k * n + c] = base ? load_as_float(base + k * stride + cs * c, a->component_type,
                                                  a->normalized)
                                  : 0.0f;
    return apply_sparse(im, index, a->normalized ? copy_normalized : copy_unnormalized, out, n);
}

/* Reads a checked unsigned integer SCALAR accessor into out (count). */
int tw_gltf_read_uints(struct tw_gltf_importer *im, uint32_t index, uint32_t *out)
{
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[index];
    uint64_t stride;
    const uint8_t *base = tw_gltf_accessor_base(im->doc, a, &stride);
    for (uint64_t k = 0; k < a->count; k++)
        out[k] = base ? tw_gltf_load_uint(base + k * stride, a->component_type) : 0;
    return apply_sparse(im, index, copy_uint, out, 1);
}

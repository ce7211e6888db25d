// The tinygltf shim (gltf-shim.h): the project's only C++. It parses with
// tinygltf, copies the raw document into plain C structs and catches every
// exception; all validation happens in C, in gltf-*.c.
//
// tinygltf is compiled here (Debian ships the header) without image decoding,
// without image writing, without external images and without its own file
// system access: the only files it can reach are buffers, through the
// caller's read callback.
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#define TINYGLTF_NO_FS
// tinygltf 2.7's writers use std::ofstream even without file system support.
#include <fstream>
#include <tiny_gltf.h>

#include <climits>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "tileworld/tiles.h"
#include "tilesets/gltf-shim.h"

static_assert(sizeof(int) == sizeof(int32_t), "glTF indices are passed as int");

namespace {

// Everything a document points into.
struct holder {
    tinygltf::Model model;
    std::vector<tw_gltf_doc_node> nodes;
    std::vector<std::vector<tw_gltf_doc_attribute>> attributes; // per primitive
    std::vector<std::vector<tw_gltf_doc_primitive>> primitives; // per mesh
    std::vector<tw_gltf_doc_mesh> meshes;
    std::vector<tw_gltf_doc_accessor> accessors;
    std::vector<tw_gltf_doc_buffer_view> buffer_views;
    std::vector<tw_gltf_doc_buffer> buffers;
    std::vector<tw_gltf_doc_material> materials;
    std::vector<tw_gltf_doc_scene> scenes;
    std::vector<tw_gltf_doc_texture> textures;
    std::vector<tw_gltf_doc_sampler> samplers;
    std::vector<tw_gltf_doc_image> images;
    std::vector<const char *> extensions_required;
};

struct io_context {
    const tw_gltf_shim_io *io;
    int error;   // the read callback's last error, 0 if none
};

bool file_exists(const std::string &, void *)
{
    // Resolution belongs to the read callback: claim every path exists so
    // that tinygltf passes the uri through unchanged and never falls back to
    // looking in the current directory.
    return true;
}

std::string expand_file_path(const std::string &path, void *)
{
    return path;
}

bool read_whole_file(std::vector<unsigned char> *out, std::string *err,
                     const std::string &path, void *user)
{
    io_context *ctx = static_cast<io_context *>(user);
    if (!ctx->io || !ctx->io->read) {
        ctx->error = TW_ERR_INVALID;
        if (err)
            *err += "external files are not allowed here";
        return false;
    }
    uint8_t *data = nullptr;
    size_t size = 0;
    int rc = ctx->io->read(ctx->io->user, path.c_str(), &data, &size);
    if (rc < 0) {
        ctx->error = rc;
        if (err)
            *err += tw_error_to_str(rc);
        free(data);
        return false;
    }
    try {
        out->assign(data, data + size);
    } catch (...) {
        free(data);
        throw;
    }
    free(data);
    return true;
}

bool write_whole_file(std::string *err, const std::string &,
                      const std::vector<unsigned char> &, void *)
{
    if (err)
        *err += "writing is not supported";
    return false;
}

// Images are never decoded here. The bytes of a data: URI are kept as they
// are (gltf-io.c decodes them); bufferView images are left in their view, whose
// range tinygltf has not checked, so their bytes are not touched.
bool keep_image(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                const unsigned char *bytes, int size, void *)
{
    if (image->bufferView < 0 && bytes && size > 0) {
        image->image.assign(bytes, bytes + size);
        image->as_is = true;
    }
    return true;
}

// tinygltf's messages span lines; the caller wants one.
void one_line(const std::string &text, char *msg, size_t msg_size)
{
    if (!msg || msg_size == 0)
        return;
    size_t n = 0;
    bool pending_sep = false;
    for (char c : text) {
        if (c == '\n' || c == '\r') {
            pending_sep = n > 0;
            continue;
        }
        if (pending_sep) {
            for (const char *s = "; "; *s && n + 1 < msg_size; s++)
                msg[n++] = *s;
            pending_sep = false;
        }
        if (n + 1 >= msg_size)
            break;
        msg[n++] = (c >= 0 && c < ' ') || c == 0x7f ? ' ' : c;
    }
    msg[n] = '\0';
}

uint32_t count32(size_t n)
{
    if (n > UINT32_MAX)
        throw std::length_error("more than 2^32 elements");
    return static_cast<uint32_t>(n);
}

template <size_t N>
uint32_t copy_values(const std::vector<double> &from, double (&to)[N])
{
    for (size_t k = 0; k < N && k < from.size(); k++)
        to[k] = from[k];
    return count32(from.size());
}

// The values of a fixed-size property, pointing into the model.
const double *values_of(const std::vector<double> &v, uint32_t *count)
{
    *count = count32(v.size());
    return v.empty() ? nullptr : v.data();
}

// A number of a KHR_texture_transform object, or fallback.
double number_of(const tinygltf::Value &v, size_t index, double fallback)
{
    if (!v.IsArray() || index >= v.ArrayLen() || !v.Get(static_cast<int>(index)).IsNumber())
        return fallback;
    return v.Get(static_cast<int>(index)).GetNumberAsDouble();
}

void export_uv_transform(const tinygltf::TextureInfo &t, tw_gltf_doc_material *d)
{
    d->uv_scale[0] = d->uv_scale[1] = 1.0;
    d->uv_texcoord = -1;
    auto it = t.extensions.find("KHR_texture_transform");
    if (it == t.extensions.end() || !it->second.IsObject())
        return;
    const tinygltf::Value &x = it->second;
    d->has_uv_transform = true;
    if (x.Has("offset")) {
        d->uv_offset[0] = number_of(x.Get("offset"), 0, 0.0);
        d->uv_offset[1] = number_of(x.Get("offset"), 1, 0.0);
    }
    if (x.Has("scale")) {
        d->uv_scale[0] = number_of(x.Get("scale"), 0, 1.0);
        d->uv_scale[1] = number_of(x.Get("scale"), 1, 1.0);
    }
    if (x.Has("rotation") && x.Get("rotation").IsNumber())
        d->uv_rotation = x.Get("rotation").GetNumberAsDouble();
    if (x.Has("texCoord") && x.Get("texCoord").IsInt())
        d->uv_texcoord = x.Get("texCoord").Get<int>();
}

void export_document(holder &h, tw_gltf_doc *out)
{
    const tinygltf::Model &m = h.model;

    h.nodes.reserve(m.nodes.size());
    for (const tinygltf::Node &n : m.nodes) {
        tw_gltf_doc_node d = {};
        d.mesh = n.mesh;
        d.children = n.children.empty() ? nullptr : n.children.data();
        d.child_count = count32(n.children.size());
        d.matrix = values_of(n.matrix, &d.matrix_count);
        d.translation = values_of(n.translation, &d.translation_count);
        d.rotation = values_of(n.rotation, &d.rotation_count);
        d.scale = values_of(n.scale, &d.scale_count);
        h.nodes.push_back(d);
    }

    size_t primitive_total = 0;
    for (const tinygltf::Mesh &mesh : m.meshes)
        primitive_total += mesh.primitives.size();
    h.attributes.reserve(primitive_total);
    h.meshes.reserve(m.meshes.size());
    h.accessors.reserve(m.accessors.size());
    h.buffer_views.reserve(m.bufferViews.size());
    h.buffers.reserve(m.buffers.size());
    h.materials.reserve(m.materials.size());
    h.textures.reserve(m.textures.size());
    h.samplers.reserve(m.samplers.size());
    h.images.reserve(m.images.size());
    h.scenes.reserve(m.scenes.size());

    h.primitives.resize(m.meshes.size());
    for (size_t k = 0; k < m.meshes.size(); k++) {
        h.primitives[k].reserve(m.meshes[k].primitives.size());
        for (const tinygltf::Primitive &p : m.meshes[k].primitives) {
            h.attributes.emplace_back();
            std::vector<tw_gltf_doc_attribute> &attrs = h.attributes.back();
            attrs.reserve(p.attributes.size());
            for (const auto &a : p.attributes)
                attrs.push_back(tw_gltf_doc_attribute{a.first.c_str(), a.second});
            tw_gltf_doc_primitive d = {};
            d.mode = p.mode;
            d.indices = p.indices;
            d.material = p.material;
            d.attribute_count = count32(attrs.size());
            d.target_count = count32(p.targets.size());
            h.primitives[k].push_back(d);
        }
    }
    // Attribute arrays are complete: now their addresses are stable.
    size_t next_attributes = 0;
    for (size_t k = 0; k < m.meshes.size(); k++) {
        for (tw_gltf_doc_primitive &d : h.primitives[k]) {
            const std::vector<tw_gltf_doc_attribute> &attrs = h.attributes[next_attributes++];
            d.attributes = attrs.empty() ? nullptr : attrs.data();
        }
        tw_gltf_doc_mesh d = {};
        d.primitives = h.primitives[k].empty() ? nullptr : h.primitives[k].data();
        d.primitive_count = count32(h.primitives[k].size());
        h.meshes.push_back(d);
    }

    for (const tinygltf::Accessor &a : m.accessors) {
        tw_gltf_doc_accessor d = {};
        d.buffer_view = a.bufferView;
        d.byte_offset = a.byteOffset;
        d.component_type = a.componentType;
        d.type = a.type;
        d.count = a.count;
        d.normalized = a.normalized;
        d.sparse = a.sparse.isSparse;
        d.sparse_count = a.sparse.count;
        d.sparse_indices_view = a.sparse.indices.bufferView;
        d.sparse_indices_offset = a.sparse.indices.byteOffset;
        d.sparse_indices_component_type = a.sparse.indices.componentType;
        d.sparse_values_view = a.sparse.values.bufferView;
        d.sparse_values_offset = a.sparse.values.byteOffset;
        h.accessors.push_back(d);
    }

    for (const tinygltf::BufferView &v : m.bufferViews)
        h.buffer_views.push_back(
            tw_gltf_doc_buffer_view{v.buffer, v.byteOffset, v.byteLength, v.byteStride});

    for (const tinygltf::Buffer &b : m.buffers)
        h.buffers.push_back(
            tw_gltf_doc_buffer{b.data.empty() ? nullptr : b.data.data(), b.data.size()});

    for (const tinygltf::Material &mat : m.materials) {
        tw_gltf_doc_material d = {};
        d.base_color_count = copy_values(mat.pbrMetallicRoughness.baseColorFactor, d.base_color);
        d.base_color_texture = mat.pbrMetallicRoughness.baseColorTexture.index;
        d.base_color_texcoord = mat.pbrMetallicRoughness.baseColorTexture.texCoord;
        export_uv_transform(mat.pbrMetallicRoughness.baseColorTexture, &d);
        h.materials.push_back(d);
    }

    for (const tinygltf::Texture &t : m.textures)
        h.textures.push_back(tw_gltf_doc_texture{t.sampler, t.source});

    for (const tinygltf::Sampler &s : m.samplers)
        h.samplers.push_back(tw_gltf_doc_sampler{s.wrapS, s.wrapT});

    for (const tinygltf::Image &i : m.images) {
        tw_gltf_doc_image d = {};
        d.uri = i.uri.empty() ? nullptr : i.uri.c_str();
        d.buffer_view = i.bufferView;
        d.mime_type = i.mimeType.c_str();
        if (i.as_is && !i.image.empty()) {
            d.data = i.image.data();
            d.size = i.image.size();
        }
        h.images.push_back(d);
    }

    for (const tinygltf::Scene &s : m.scenes)
        h.scenes.push_back(tw_gltf_doc_scene{s.nodes.empty() ? nullptr : s.nodes.data(),
                                             count32(s.nodes.size())});

    for (const std::string &e : m.extensionsRequired)
        h.extensions_required.push_back(e.c_str());

    out->version = m.asset.version.c_str();
    out->min_version = m.asset.minVersion.c_str();
    out->default_scene = m.defaultScene;
    out->extensions_required = h.extensions_required.data();
    out->extensions_required_count = count32(h.extensions_required.size());
    out->nodes = h.nodes.data();
    out->node_count = count32(h.nodes.size());
    out->meshes = h.meshes.data();
    out->mesh_count = count32(h.meshes.size());
    out->accessors = h.accessors.data();
    out->accessor_count = count32(h.accessors.size());
    out->buffer_views = h.buffer_views.data();
    out->buffer_view_count = count32(h.buffer_views.size());
    out->buffers = h.buffers.data();
    out->buffer_count = count32(h.buffers.size());
    out->materials = h.materials.data();
    out->material_count = count32(h.materials.size());
    out->scenes = h.scenes.data();
    out->scene_count = count32(h.scenes.size());
    out->textures = h.textures.data();
    out->texture_count = count32(h.textures.size());
    out->samplers = h.samplers.data();
    out->sampler_count = count32(h.samplers.size());
    out->images = h.images.data();
    out->image_count = count32(h.images.size());
}

// Room for the arrays tinygltf fills (it clear()s them, which keeps it).
void reserve_model(tinygltf::Model &m, const uint64_t *counts)
{
    if (!counts)
        return;
    m.accessors.reserve(counts[TW_GLTF_ACCESSORS]);
    m.animations.reserve(counts[TW_GLTF_ANIMATIONS]);
    m.buffers.reserve(counts[TW_GLTF_BUFFERS]);
    m.bufferViews.reserve(counts[TW_GLTF_BUFFER_VIEWS]);
    m.cameras.reserve(counts[TW_GLTF_CAMERAS]);
    m.images.reserve(counts[TW_GLTF_IMAGES]);
    m.materials.reserve(counts[TW_GLTF_MATERIALS]);
    m.meshes.reserve(counts[TW_GLTF_MESHES]);
    m.nodes.reserve(counts[TW_GLTF_NODES]);
    m.samplers.reserve(counts[TW_GLTF_SAMPLERS]);
    m.scenes.reserve(counts[TW_GLTF_SCENES]);
    m.skins.reserve(counts[TW_GLTF_SKINS]);
    m.textures.reserve(counts[TW_GLTF_TEXTURES]);
}

int load(const uint8_t *data, size_t size, const tw_gltf_shim_io *io, const uint64_t *reserve,
         tw_gltf_doc *out, char *msg, size_t msg_size)
{
    if (size > UINT_MAX) {
        one_line("larger than tinygltf can read (4 GiB)", msg, msg_size);
        return TW_ERR_LIMIT;
    }
    io_context ctx = {io, 0};
    tinygltf::FsCallbacks fs = {};
    fs.FileExists = file_exists;
    fs.ExpandFilePath = expand_file_path;
    fs.ReadWholeFile = read_whole_file;
    fs.WriteWholeFile = write_whole_file;
    fs.user_data = &ctx;

    tinygltf::TinyGLTF loader;
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(keep_image, nullptr);

    holder *h = new holder();
    std::string err, warn;
    try {
        reserve_model(h->model, reserve);
    } catch (...) {
        delete h;
        throw;
    }
    const bool binary = size >= 4 && memcmp(data, "glTF", 4) == 0;
    bool ok;
    try {
        if (binary)
            ok = loader.LoadBinaryFromMemory(&h->model, &err, &warn, data,
                                             static_cast<unsigned int>(size), "");
        else
            ok = loader.LoadASCIIFromString(&h->model, &err, &warn,
                                            reinterpret_cast<const char *>(data),
                                            static_cast<unsigned int>(size), "");
        if (ok)
            export_document(*h, out);
    } catch (...) {
        delete h;
        throw;
    }
    if (!ok) {
        delete h;
        *out = tw_gltf_doc{};
        one_line(err.empty() ? "tinygltf refused the document" : "tinygltf: " + err, msg,
                 msg_size);
        return ctx.error ? ctx.error : TW_ERR_FORMAT;
    }
    out->internal = h;
    return TW_OK;
}

} // namespace

extern "C" uint64_t tw_gltf_shim_element_bytes(enum tw_gltf_kind kind)
{
    switch (kind) {
    case TW_GLTF_ACCESSORS: return sizeof(tinygltf::Accessor) + sizeof(tw_gltf_doc_accessor);
    case TW_GLTF_ANIMATIONS: return sizeof(tinygltf::Animation);
    case TW_GLTF_BUFFERS: return sizeof(tinygltf::Buffer) + sizeof(tw_gltf_doc_buffer);
    case TW_GLTF_BUFFER_VIEWS:
        return sizeof(tinygltf::BufferView) + sizeof(tw_gltf_doc_buffer_view);
    case TW_GLTF_CAMERAS: return sizeof(tinygltf::Camera);
    case TW_GLTF_IMAGES: return sizeof(tinygltf::Image) + sizeof(tw_gltf_doc_image);
    case TW_GLTF_MATERIALS: return sizeof(tinygltf::Material) + sizeof(tw_gltf_doc_material);
    case TW_GLTF_MESHES:
        return sizeof(tinygltf::Mesh) + sizeof(tw_gltf_doc_mesh) +
               sizeof(std::vector<tw_gltf_doc_primitive>);
    case TW_GLTF_NODES: return sizeof(tinygltf::Node) + sizeof(tw_gltf_doc_node);
    case TW_GLTF_SAMPLERS: return sizeof(tinygltf::Sampler) + sizeof(tw_gltf_doc_sampler);
    case TW_GLTF_SCENES: return sizeof(tinygltf::Scene) + sizeof(tw_gltf_doc_scene);
    case TW_GLTF_SKINS: return sizeof(tinygltf::Skin);
    case TW_GLTF_TEXTURES: return sizeof(tinygltf::Texture) + sizeof(tw_gltf_doc_texture);
    case TW_GLTF_PRIMITIVES:
        return sizeof(tinygltf::Primitive) + sizeof(tw_gltf_doc_primitive) +
               sizeof(std::vector<tw_gltf_doc_attribute>);
    default: return 0;
    }
}

extern "C" int tw_gltf_shim_load(const uint8_t *data, size_t size, const tw_gltf_shim_io *io,
                                 const uint64_t reserve[TW_GLTF_KIND_COUNT], tw_gltf_doc *out,
                                 char *msg, size_t msg_size)
{
    if (msg && msg_size)
        msg[0] = '\0';
    if (!out)
        return TW_ERR_INVALID;
    *out = tw_gltf_doc{};
    if (!data && size)
        return TW_ERR_INVALID;
    static const uint8_t empty = 0;
    try {
        return load(data ? data : &empty, size, io, reserve, out, msg, msg_size);
    } catch (const std::bad_alloc &) {
        *out = tw_gltf_doc{};
        one_line("tinygltf ran out of memory (std::bad_alloc)", msg, msg_size);
        return TW_ERR_NOMEM;
    } catch (const std::exception &e) {
        *out = tw_gltf_doc{};
        try {
            one_line(std::string("tinygltf threw ") + e.what(), msg, msg_size);
        } catch (...) {
            one_line("tinygltf threw an exception", msg, msg_size);
        }
        return TW_ERR_FORMAT;
    } catch (...) {
        *out = tw_gltf_doc{};
        one_line("tinygltf threw an unknown exception", msg, msg_size);
        return TW_ERR_FORMAT;
    }
}

extern "C" void tw_gltf_shim_free(tw_gltf_doc *doc)
{
    if (!doc)
        return;
    delete static_cast<holder *>(doc->internal);
    *doc = tw_gltf_doc{};
}

/*
 * Benchmark (meson benchmark, not a test): where should the HZB methods
 * build their depth pyramid and test their boxes on this GPU? On the CPU
 * after a glReadPixels of the depth (what cull/hzb.c does), or in compute
 * shaders on the GPU (the niagara / Nanite way, results read back or left
 * for indirect draws)? Measured at 640 x 360 and 1280 x 720 in wall and
 * process CPU time (on llvmpipe the GPU's threads are the process's), each
 * step after glFinish so that only its own cost is counted:
 *
 *   readback      glReadPixels of a DEPTH32F buffer as floats
 *   cpu build     tw_hzb_build over it (every level, level 0 full size)
 *   cpu test      N boxes through tw_hzb_visible
 *   gpu build     compute reduction depth texture -> R32F mip chain
 *                 (level 0 at half size, one dispatch per level)
 *   gpu test      N boxes tested by a compute shader, results read back
 *
 * Usage: bench-hzb [boxes] [repeats]
 */
#include <GL/glcorearb.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tileworld/context.h"
#include "cull/cull-private.h"

#define GL_FUNCS(X) \
    X(PFNGLGETERRORPROC, GetError) X(PFNGLGENFRAMEBUFFERSPROC, GenFramebuffers) \
    X(PFNGLBINDFRAMEBUFFERPROC, BindFramebuffer) X(PFNGLGENTEXTURESPROC, GenTextures) \
    X(PFNGLBINDTEXTUREPROC, BindTexture) X(PFNGLTEXSTORAGE2DPROC, TexStorage2D) \
    X(PFNGLTEXPARAMETERIPROC, TexParameteri) \
    X(PFNGLFRAMEBUFFERTEXTURE2DPROC, FramebufferTexture2D) \
    X(PFNGLCHECKFRAMEBUFFERSTATUSPROC, CheckFramebufferStatus) X(PFNGLVIEWPORTPROC, Viewport) \
    X(PFNGLCLIPCONTROLPROC, ClipControl) X(PFNGLCLEARDEPTHPROC, ClearDepth) \
    X(PFNGLCLEARPROC, Clear) X(PFNGLENABLEPROC, Enable) X(PFNGLDEPTHFUNCPROC, DepthFunc) \
    X(PFNGLCREATESHADERPROC, CreateShader) X(PFNGLSHADERSOURCEPROC, ShaderSource) \
    X(PFNGLCOMPILESHADERPROC, CompileShader) X(PFNGLGETSHADERIVPROC, GetShaderiv) \
    X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog) X(PFNGLCREATEPROGRAMPROC, CreateProgram) \
    X(PFNGLATTACHSHADERPROC, AttachShader) X(PFNGLLINKPROGRAMPROC, LinkProgram) \
    X(PFNGLGETPROGRAMIVPROC, GetProgramiv) X(PFNGLUSEPROGRAMPROC, UseProgram) \
    X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation) X(PFNGLUNIFORM1IPROC, Uniform1i) \
    X(PFNGLUNIFORM1FPROC, Uniform1f) X(PFNGLUNIFORM2IPROC, Uniform2i) \
    X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv) X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays) \
    X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray) X(PFNGLGENBUFFERSPROC, GenBuffers) \
    X(PFNGLBINDBUFFERPROC, BindBuffer) X(PFNGLBUFFERDATAPROC, BufferData) \
    X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray) \
    X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer) X(PFNGLDRAWARRAYSPROC, DrawArrays) \
    X(PFNGLFINISHPROC, Finish) X(PFNGLREADPIXELSPROC, ReadPixels) \
    X(PFNGLPIXELSTOREIPROC, PixelStorei) X(PFNGLDISPATCHCOMPUTEPROC, DispatchCompute) \
    X(PFNGLMEMORYBARRIERPROC, MemoryBarrier) X(PFNGLBINDIMAGETEXTUREPROC, BindImageTexture) \
    X(PFNGLACTIVETEXTUREPROC, ActiveTexture) X(PFNGLBINDBUFFERBASEPROC, BindBufferBase) \
    X(PFNGLGETBUFFERSUBDATAPROC, GetBufferSubData) X(PFNGLGETSTRINGPROC, GetString)

static struct {
#define MEMBER(t, n) t n;
    GL_FUNCS(MEMBER)
#undef MEMBER
} gl;

static double wall_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static double cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static GLuint program(const char *vs, const char *fs, const char *cs)
{
    const char *src[3] = {vs, fs, cs};
    const GLenum type[3] = {GL_VERTEX_SHADER, GL_FRAGMENT_SHADER, GL_COMPUTE_SHADER};
    const GLuint p = gl.CreateProgram();
    for (int k = 0; k < 3; k++) {
        if (!src[k])
            continue;
        const GLuint s = gl.CreateShader(type[k]);
        gl.ShaderSource(s, 1, &src[k], NULL);
        gl.CompileShader(s);
        GLint ok = 0;
        gl.GetShaderiv(s, GL_COMPILE_STATUS, &ok);
        if (!ok) {
            char log[2048];
            gl.GetShaderInfoLog(s, sizeof(log), NULL, log);
            fprintf(stderr, "shader: %s\n", log);
            exit(1);
        }
        gl.AttachShader(p, s);
    }
    gl.LinkProgram(p);
    GLint ok = 0;
    gl.GetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        fprintf(stderr, "link failed\n");
        exit(1);
    }
    return p;
}

static const char *const scene_vs =
    "#version 450 core\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "uniform mat4 u_vp;\n"
    "void main() { gl_Position = u_vp * vec4(a_pos, 1.0); }\n";
static const char *const scene_fs =
    "#version 450 core\n"
    "out vec4 o;\n"
    "void main() { o = vec4(1.0); }\n";

/* Level 0 of the pyramid (half size) from the depth texture: the farthest
 * (reversed: smallest) of each 2 x 2 block, odd edges clamped. */
static const char *const reduce_first_cs =
    "#version 450 core\n"
    "layout(local_size_x = 8, local_size_y = 8) in;\n"
    "uniform sampler2D u_depth;\n"
    "uniform ivec2 u_src;\n"
    "layout(r32f, binding = 1) writeonly uniform image2D u_dst;\n"
    "void main() {\n"
    "    ivec2 p = ivec2(gl_GlobalInvocationID.xy), d = imageSize(u_dst);\n"
    "    if (p.x >= d.x || p.y >= d.y) return;\n"
    "    ivec2 s = 2 * p, m = u_src - 1;\n"
    "    float a = texelFetch(u_depth, min(s, m), 0).r;\n"
    "    float b = texelFetch(u_depth, min(s + ivec2(1, 0), m), 0).r;\n"
    "    float c = texelFetch(u_depth, min(s + ivec2(0, 1), m), 0).r;\n"
    "    float e = texelFetch(u_depth, min(s + ivec2(1, 1), m), 0).r;\n"
    "    imageStore(u_dst, p, vec4(min(min(a, b), min(c, e))));\n"
    "}\n";
static const char *const reduce_cs =
    "#version 450 core\n"
    "layout(local_size_x = 8, local_size_y = 8) in;\n"
    "layout(r32f, binding = 0) readonly uniform image2D u_srcimg;\n"
    "layout(r32f, binding = 1) writeonly uniform image2D u_dst;\n"
    "void main() {\n"
    "    ivec2 p = ivec2(gl_GlobalInvocationID.xy), d = imageSize(u_dst);\n"
    "    if (p.x >= d.x || p.y >= d.y) return;\n"
    "    ivec2 s = 2 * p, m = imageSize(u_srcimg) - 1;\n"
    "    float a = imageLoad(u_srcimg, min(s, m)).r;\n"
    "    float b = imageLoad(u_srcimg, min(s + ivec2(1, 0), m)).r;\n"
    "    float c = imageLoad(u_srcimg, min(s + ivec2(0, 1), m)).r;\n"
    "    float e = imageLoad(u_srcimg, min(s + ivec2(1, 1), m)).r;\n"
    "    imageStore(u_dst, p, vec4(min(min(a, b), min(c, e))));\n"
    "}\n";
/* One box per invocation: rectangle, level with <= 8 texels a side, the
 * farthest texel against the box's nearest depth (reversed). */
static const char *const test_cs =
    "#version 450 core\n"
    "layout(local_size_x = 64) in;\n"
    "layout(std430, binding = 0) readonly buffer Boxes { vec4 boxes[]; };\n"
    "layout(std430, binding = 1) writeonly buffer Visible { uint visible[]; };\n"
    "uniform sampler2D u_pyramid;\n"
    "uniform mat4 u_vp;\n"
    "uniform ivec2 u_size;\n"     /* the depth buffer */
    "uniform int u_levels;\n"
    "uniform int u_count;\n"
    "uniform float u_near;\n"
    "void main() {\n"
    "    uint i = gl_GlobalInvocationID.x;\n"
    "    if (i >= uint(u_count)) return;\n"
    "    vec3 lo = boxes[2u * i].xyz, hi = boxes[2u * i + 1u].xyz;\n"
    "    vec2 r0 = vec2(1e30), r1 = vec2(-1e30); float zmax = -1e30; bool vis = false;\n"
    "    for (int c = 0; c < 8; c++) {\n"
    "        vec3 p = vec3((c & 1) != 0 ? hi.x : lo.x, (c & 2) != 0 ? hi.y : lo.y,\n"
    "                      (c & 4) != 0 ? hi.z : lo.z);\n"
    "        vec4 q = u_vp * vec4(p, 1.0);\n"
    "        if (q.w <= u_near) vis = true;\n"
    "        vec2 s = q.xy / q.w; r0 = min(r0, s); r1 = max(r1, s); zmax = max(zmax, q.z / q.w);\n"
    "    }\n"
    "    if (!vis) {\n"
    "        vec2 full = vec2(u_size);\n"
    "        ivec2 top = ivec2(full) - 1;\n"
    "        ivec2 a = clamp(ivec2(floor((r0 * 0.5 + 0.5) * full - 0.5)), ivec2(0), top) / 2;\n"
    "        ivec2 b = clamp(ivec2(floor((r1 * 0.5 + 0.5) * full - 0.5)) + 1, ivec2(0), top) / 2;\n"
    "        int k = 0;\n"
    "        while (k + 1 < u_levels && any(greaterThanEqual((b >> k) - (a >> k), ivec2(8))))\n"
    "            k++;\n"
    "        float far_d = 1.0;\n"
    "        for (int y = a.y >> k; y <= (b.y >> k); y++)\n"
    "            for (int x = a.x >> k; x <= (b.x >> k); x++)\n"
    "                far_d = min(far_d, texelFetch(u_pyramid, ivec2(x, y), k).r);\n"
    "        vis = !(zmax < far_d * (1.0 - 1e-6));\n"
    "    }\n"
    "    visible[i] = vis ? 1u : 0u;\n"
    "}\n";

enum { MAX_REPEATS = 1000 };

/* Per-repeat times of one step; reported as medians (the machine is shared). */
struct result {
    double wall[MAX_REPEATS], cpu[MAX_REPEATS];
    int n;
};

static void add(struct result *r, double wall, double cpu)
{
    if (r->n < MAX_REPEATS) {
        r->wall[r->n] = wall;
        r->cpu[r->n++] = cpu;
    }
}

static int compare_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof(*v), compare_double);
    return n ? v[n / 2] : 0.0;
}

static void report(const char *what, uint32_t w, uint32_t h, struct result *r)
{
    printf("%4ux%-4u %-28s wall %8.3f ms   cpu %8.3f ms\n", w, h, what, median(r->wall, r->n),
           median(r->cpu, r->n));
}

static void bench_size(uint32_t W, uint32_t H, uint32_t nboxes, int repeats)
{
    if (gl.GetError() != GL_NO_ERROR)
        exit(1);
    /* A depth texture (reversed float depth) and a scene of random quads. */
    GLuint fbo, depth_tex, pyramid;
    gl.GenTextures(1, &depth_tex);
    gl.BindTexture(GL_TEXTURE_2D, depth_tex);
    gl.TexStorage2D(GL_TEXTURE_2D, 1, GL_DEPTH_COMPONENT32F, (GLsizei)W, (GLsizei)H);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    gl.GenFramebuffers(1, &fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl.FramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, depth_tex, 0);
    if (gl.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        fprintf(stderr, "framebuffer incomplete\n");
        exit(1);
    }
    /* GL's mip levels halve rounding down: a power-of-two pyramid (at least
     * half the buffer) keeps every texel's 2 x 2 block whole; reads past the
     * buffer's edge are clamped to it. */
    uint32_t pw = 1, ph = 1;
    while (pw < (W + 1) / 2)
        pw *= 2;
    while (ph < (H + 1) / 2)
        ph *= 2;
    int levels = 1;
    for (uint32_t m = pw > ph ? pw : ph; m > 1; m /= 2)
        levels++;
    gl.GenTextures(1, &pyramid);
    gl.BindTexture(GL_TEXTURE_2D, pyramid);
    gl.TexStorage2D(GL_TEXTURE_2D, levels, GL_R32F, (GLsizei)pw, (GLsizei)ph);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST_MIPMAP_NEAREST);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);

    struct tw_view v;
    const float eye[3] = {0, 1.7f, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 60.0f, (float)W / (float)H,
                       0.2f, 1000.0f);
    v.view_distance = 900.0f;
    v.frame = 1;
    /* 400 random vertical quads 5-300 m ahead. */
    enum { QUADS = 400 };
    float *tri = malloc(sizeof(float) * QUADS * 18);
    srand(1);
    for (int q = 0; q < QUADS; q++) {
        const float z = 5.0f + 295.0f * (float)rand() / (float)RAND_MAX;
        const float x = (2.0f * (float)rand() / (float)RAND_MAX - 1.0f) * z;
        const float s = 0.05f * z * (1.0f + 3.0f * (float)rand() / (float)RAND_MAX);
        const float c[4][3] = {{x - s, 0, z}, {x + s, 0, z}, {x + s, 2 * s, z}, {x - s, 2 * s, z}};
        const int order[6] = {0, 1, 2, 0, 2, 3};
        for (int k = 0; k < 6; k++)
            memcpy(&tri[q * 18 + k * 3], c[order[k]], sizeof(c[0]));
    }
    GLuint vao, vbo;
    gl.GenVertexArrays(1, &vao);
    gl.BindVertexArray(vao);
    gl.GenBuffers(1, &vbo);
    gl.BindBuffer(GL_ARRAY_BUFFER, vbo);
    gl.BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(sizeof(float) * QUADS * 18), tri, GL_STATIC_DRAW);
    gl.EnableVertexAttribArray(0);
    gl.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 12, (const void *)0);
    free(tri);
    const GLuint scene = program(scene_vs, scene_fs, NULL);
    gl.UseProgram(scene);
    gl.UniformMatrix4fv(gl.GetUniformLocation(scene, "u_vp"), 1, GL_FALSE, v.view_proj_rz);
    gl.Viewport(0, 0, (GLsizei)W, (GLsizei)H);
    gl.ClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
    gl.ClearDepth(0.0);
    gl.Clear(GL_DEPTH_BUFFER_BIT);
    gl.Enable(GL_DEPTH_TEST);
    gl.DepthFunc(GL_GEQUAL);
    gl.DrawArrays(GL_TRIANGLES, 0, QUADS * 6);
    gl.Finish();

    /* Boxes: random, 2-400 m ahead. */
    float *boxes = malloc(sizeof(float) * 8 * nboxes);
    struct tw_box *tboxes = malloc(sizeof(*tboxes) * nboxes);
    for (uint32_t k = 0; k < nboxes; k++) {
        const float z = 2.0f + 398.0f * (float)rand() / (float)RAND_MAX;
        const float x = (2.0f * (float)rand() / (float)RAND_MAX - 1.0f) * z;
        const float s = 0.02f * z * (1.0f + 4.0f * (float)rand() / (float)RAND_MAX);
        tboxes[k] = (struct tw_box){{x - s, 0, z}, {x + s, 2 * s, z + s}};
        const float b[8] = {x - s, 0, z, 0, x + s, 2 * s, z + s, 0};
        memcpy(&boxes[8 * k], b, sizeof(b));
    }

    /* CPU: readback, build, test. */
    struct tw_hzb *hzb = NULL;
    tw_hzb_create(&hzb);
    float *buf = tw_hzb_depth_buffer(hzb, W, H);
    gl.PixelStorei(GL_PACK_ALIGNMENT, 4);
    static struct result rb, build, test, cpu_total, gbuild, gtest, gpu_total;
    memset(&rb, 0, sizeof(rb));
    memset(&build, 0, sizeof(build));
    memset(&test, 0, sizeof(test));
    memset(&cpu_total, 0, sizeof(cpu_total));
    memset(&gbuild, 0, sizeof(gbuild));
    memset(&gtest, 0, sizeof(gtest));
    memset(&gpu_total, 0, sizeof(gpu_total));
    uint32_t cpu_visible = 0;
    for (int r = 0; r < repeats + 1; r++) {
        const double w0 = wall_ms(), c0 = cpu_ms();
        gl.ReadPixels(0, 0, (GLsizei)W, (GLsizei)H, GL_DEPTH_COMPONENT, GL_FLOAT, buf);
        const double w1 = wall_ms(), c1 = cpu_ms();
        tw_hzb_build(hzb, true);
        const double w2 = wall_ms(), c2 = cpu_ms();
        uint32_t vis = 0;
        for (uint32_t k = 0; k < nboxes; k++)
            vis += tw_hzb_visible(hzb, &v, &tboxes[k], NULL);
        const double w3 = wall_ms(), c3 = cpu_ms();
        if (r == 0)
            continue;   /* warm-up */
        add(&rb, w1 - w0, c1 - c0);
        add(&build, w2 - w1, c2 - c1);
        add(&test, w3 - w2, c3 - c2);
        add(&cpu_total, w3 - w0, c3 - c0);
        cpu_visible = vis;
        buf = tw_hzb_depth_buffer(hzb, W, H);
    }
    report("readback (glReadPixels)", W, H, &rb);
    report("cpu build", W, H, &build);
    char what[64];
    snprintf(what, sizeof(what), "cpu test, %u boxes", nboxes);
    report(what, W, H, &test);
    report("cpu: readback+build+test", W, H, &cpu_total);

    /* GPU: reduction, test, results back. */
    const GLuint first = program(NULL, NULL, reduce_first_cs);
    const GLuint rest = program(NULL, NULL, reduce_cs);
    const GLuint tester = program(NULL, NULL, test_cs);
    GLuint ssbo[2];
    gl.GenBuffers(2, ssbo);
    gl.BindBuffer(GL_SHADER_STORAGE_BUFFER, ssbo[0]);
    gl.BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(sizeof(float) * 8 * nboxes), boxes,
                  GL_STATIC_DRAW);
    gl.BindBuffer(GL_SHADER_STORAGE_BUFFER, ssbo[1]);
    gl.BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(sizeof(uint32_t) * nboxes), NULL,
                  GL_DYNAMIC_READ);
    uint32_t *results = malloc(sizeof(uint32_t) * nboxes);
    uint32_t gpu_visible = 0;
    for (int r = 0; r < repeats + 1; r++) {
        const double w0 = wall_ms(), c0 = cpu_ms();
        gl.UseProgram(first);
        gl.ActiveTexture(GL_TEXTURE0);
        gl.BindTexture(GL_TEXTURE_2D, depth_tex);
        gl.Uniform1i(gl.GetUniformLocation(first, "u_depth"), 0);
        gl.Uniform2i(gl.GetUniformLocation(first, "u_src"), (GLint)W, (GLint)H);
        gl.BindImageTexture(1, pyramid, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_R32F);
        gl.DispatchCompute((pw + 7) / 8, (ph + 7) / 8, 1);
        uint32_t lw = pw, lh = ph;
        gl.UseProgram(rest);
        for (int k = 1; k < levels; k++) {
            gl.MemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
            lw = lw > 1 ? lw / 2 : 1;
            lh = lh > 1 ? lh / 2 : 1;
            gl.BindImageTexture(0, pyramid, k - 1, GL_FALSE, 0, GL_READ_ONLY, GL_R32F);
            gl.BindImageTexture(1, pyramid, k, GL_FALSE, 0, GL_WRITE_ONLY, GL_R32F);
            gl.DispatchCompute((lw + 7) / 8, (lh + 7) / 8, 1);
        }
        gl.MemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
        gl.Finish();
        const double w1 = wall_ms(), c1 = cpu_ms();
        gl.UseProgram(tester);
        gl.BindTexture(GL_TEXTURE_2D, pyramid);
        gl.Uniform1i(gl.GetUniformLocation(tester, "u_pyramid"), 0);
        gl.UniformMatrix4fv(gl.GetUniformLocation(tester, "u_vp"), 1, GL_FALSE, v.view_proj_rz);
        gl.Uniform2i(gl.GetUniformLocation(tester, "u_size"), (GLint)W, (GLint)H);
        gl.Uniform1i(gl.GetUniformLocation(tester, "u_levels"), levels);
        gl.Uniform1i(gl.GetUniformLocation(tester, "u_count"), (GLint)nboxes);
        gl.Uniform1f(gl.GetUniformLocation(tester, "u_near"), v.near_plane);
        gl.BindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, ssbo[0]);
        gl.BindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, ssbo[1]);
        gl.DispatchCompute((nboxes + 63) / 64, 1, 1);
        gl.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
        gl.BindBuffer(GL_SHADER_STORAGE_BUFFER, ssbo[1]);
        gl.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)(sizeof(uint32_t) * nboxes),
                            results);
        const double w2 = wall_ms(), c2 = cpu_ms();
        if (r == 0)
            continue;
        add(&gbuild, w1 - w0, c1 - c0);
        add(&gtest, w2 - w1, c2 - c1);
        add(&gpu_total, w2 - w0, c2 - c0);
        gpu_visible = 0;
        for (uint32_t k = 0; k < nboxes; k++)
            gpu_visible += results[k] != 0;
    }
    report("gpu build (compute)", W, H, &gbuild);
    snprintf(what, sizeof(what), "gpu test + readback, %u", nboxes);
    report(what, W, H, &gtest);
    report("gpu: build+test", W, H, &gpu_total);
    printf("%4ux%-4u boxes visible: cpu %u, gpu %u of %u (the gpu test does not split boxes)\n",
           W, H, cpu_visible, gpu_visible, nboxes);
    const GLenum err = gl.GetError();
    if (err != GL_NO_ERROR) {
        fprintf(stderr, "GL error 0x%x\n", err);
        exit(1);
    }
    free(results);
    free(boxes);
    free(tboxes);
    tw_hzb_destroy(hzb);
}

int main(int argc, char **argv)
{
    const uint32_t nboxes = argc > 1 ? (uint32_t)atoi(argv[1]) : 2000;
    int repeats = argc > 2 ? atoi(argv[2]) : 30;
    if (repeats < 1 || repeats > MAX_REPEATS)
        repeats = 30;
    struct tw_context *ctx = NULL;
    if (tw_context_create_headless(64, 64, NULL, &ctx) != TW_OK) {
        fprintf(stderr, "no headless context\n");
        return 1;
    }
    const tw_gl_get_proc_fn get = tw_context_get_proc(ctx);
#define LOAD(t, n) \
    gl.n = (t)get("gl" #n); \
    if (!gl.n) { \
        fprintf(stderr, "no gl" #n "\n"); \
        return 1; \
    }
    GL_FUNCS(LOAD)
#undef LOAD
    printf("%s; %u boxes, %d repeats, times per frame\n",
           (const char *)gl.GetString(GL_RENDERER), nboxes, repeats);
    bench_size(640, 360, nboxes, repeats);
    bench_size(1280, 720, nboxes, repeats);
    tw_context_destroy(ctx);
    return 0;
}

/* The GL programs: compiling and linking, the renderer's shader sources and
 * uniform locations (programs.h). */
#include "runtime/programs.h"
#include "tiles/tiles-internal.h"

#include <string.h>

static const char *const scene_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "layout(location = 1) in vec3 a_normal;\n"
    "layout(location = 2) in vec4 a_color;\n"
    /* the draw's record (runtime/draws.c): instanced attributes */
    "layout(location = 3) in vec4 i_model0;\n"
    "layout(location = 4) in vec4 i_model1;\n"
    "layout(location = 5) in vec4 i_model2;\n"
    "layout(location = 6) in vec4 i_offset;\n"
    "layout(location = 7) in vec4 i_color;\n"
    "uniform mat4 u_view_proj;\n"
    "out vec3 v_normal;\n"
    "out vec3 v_pos;\n"
    "out vec3 v_color;\n"
    "flat out vec3 v_material;\n"
    "flat out uint v_id;\n"
    "invariant gl_Position;\n"
    "void main() {\n"
    "    vec4 p = vec4(a_pos, 1.0);\n"
    "    vec3 w = vec3(dot(i_model0, p), dot(i_model1, p), dot(i_model2, p)) + i_offset.xyz;\n"
    "    v_normal = vec3(dot(i_model0.xyz, a_normal), dot(i_model1.xyz, a_normal),\n"
    "                    dot(i_model2.xyz, a_normal));\n"
    "    v_pos = w;\n"
    "    v_color = a_color.rgb;\n"
    "    v_material = i_color.rgb;\n"
    "    v_id = uint(i_offset.w);\n"
    "    gl_Position = u_view_proj * vec4(w, 1.0);\n"
    "}\n";

static const char *const scene_fs =
    "#version 330 core\n"
    "in vec3 v_normal;\n"
    "in vec3 v_pos;\n"
    "in vec3 v_color;\n"
    "flat in vec3 v_material;\n"
    "uniform vec3 u_eye;\n"
    "uniform vec2 u_fog;\n"
    "out vec4 o_color;\n"
    "void main() {\n"
    "    vec3 n = normalize(v_normal);\n"
    "    vec3 sun = normalize(vec3(0.45, 0.8, 0.3));\n"
    "    float light = 0.38 + 0.62 * max(dot(n, sun), 0.0) + 0.08 * max(-n.x, 0.0);\n"
    "    vec3 c = v_material * v_color * light;\n"
    "    float f = clamp((distance(v_pos, u_eye) - u_fog.x) / u_fog.y, 0.0, 0.85);\n"
    "    o_color = vec4(mix(c, vec3(0.70, 0.80, 0.92), f), 1.0);\n"
    "}\n";

/* The ID pass shares scene_vs (whose position is invariant) and the normal
 * pass's depth function, culling and clip control, and has no geometry
 * shader: it rasterises exactly the fragments, at exactly the depths, that
 * the normal pass would for the same clusters (DESIGN §8), so that the
 * oracle sees what the user sees. */
static const char *const id_fs =
    "#version 330 core\n"
    "flat in uint v_id;\n"
    "out uint o_id;\n"
    "void main() {\n"
    "    o_id = v_id;\n"
    "}\n";

static const char *const box_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_corner;\n"
    "uniform mat4 u_view_proj;\n"
    "uniform vec3 u_min;\n"
    "uniform vec3 u_max;\n"
    "void main() {\n"
    "    gl_Position = u_view_proj * vec4(mix(u_min, u_max, a_corner), 1.0);\n"
    "}\n";

/* Query boxes: the box of each instance from per-instance attributes. */
static const char *const query_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_corner;\n"
    "layout(location = 1) in vec3 i_min;\n"
    "layout(location = 2) in vec3 i_max;\n"
    "uniform mat4 u_view_proj;\n"
    "void main() {\n"
    "    gl_Position = u_view_proj * vec4(mix(i_min, i_max, a_corner), 1.0);\n"
    "}\n";

static const char *const box_fs =
    "#version 330 core\n"
    "out vec4 o_color;\n"
    "void main() { o_color = vec4(1.0); }\n";

/* Debug edges: each line becomes a quad u_width pixels wide, so that boxes
 * stay readable where a core profile offers only 1-pixel lines. An end
 * behind the eye is first moved to just in front of it. */
static const char *const line_gs =
    "#version 330 core\n"
    "layout(lines) in;\n"
    "layout(triangle_strip, max_vertices = 4) out;\n"
    "uniform vec3 u_viewport;\n"   /* width, height in pixels; line width in pixels */
    "void main() {\n"
    "    vec4 a = gl_in[0].gl_Position, b = gl_in[1].gl_Position;\n"
    "    const float eps = 1e-3;\n"
    "    if (a.w < eps && b.w < eps) return;\n"
    "    if (a.w < eps) a = mix(a, b, (eps - a.w) / (b.w - a.w));\n"
    "    else if (b.w < eps) b = mix(b, a, (eps - b.w) / (a.w - b.w));\n"
    "    vec2 d = (b.xy / b.w - a.xy / a.w) * u_viewport.xy;\n"
    "    if (dot(d, d) < 1e-12) d = vec2(1.0, 0.0);\n"
    "    vec2 n = normalize(vec2(-d.y, d.x)) * u_viewport.z / u_viewport.xy;\n"
    "    gl_Position = a + vec4(n * a.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = a - vec4(n * a.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = b + vec4(n * b.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = b - vec4(n * b.w, 0.0, 0.0); EmitVertex();\n"
    "    EndPrimitive();\n"
    "}\n";

static const char *const color_fs =
    "#version 330 core\n"
    "uniform vec4 u_color;\n"
    "out vec4 o_color;\n"
    "void main() { o_color = u_color; }\n";

/* Logs why a shader did not compile or a program did not link (doing:
 * "compiling a shader", what: "a shader does not compile"): the driver out
 * of memory, once, else a bug with the driver's message. */
static void report(const struct tw_gl *gl, const struct tw_log *log, bool *out_of_memory,
                   const char *doing, const char *what, const char *msg)
{
    if (gl->GetError() == GL_OUT_OF_MEMORY && !*out_of_memory) {
        *out_of_memory = true;
        tw_log_printf(log, TW_LOG_ERROR, "the OpenGL driver ran out of memory %s", doing);
    } else if (!*out_of_memory) {
        tw_log_printf(log, TW_LOG_ERROR, "%s (a bug): %s", what, msg);
    }
}

static GLuint compile(const struct tw_gl *gl, const struct tw_log *log, GLenum type,
                      const char *src, bool *out_of_memory)
{
    GLuint s = gl->CreateShader(type);
    gl->ShaderSource(s, 1, &src, NULL);
    gl->CompileShader(s);
    GLint ok = 0;
    gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char msg[1024] = "";
        gl->GetShaderInfoLog(s, sizeof(msg), NULL, msg);
        report(gl, log, out_of_memory, "compiling a shader", "a shader does not compile", msg);
        gl->DeleteShader(s);
        return 0;
    }
    return s;
}

/* Links the n compiled shaders (all non-zero) into a program, then deletes
 * them: its name, or 0 (logged as tw_programs_link says). */
static GLuint link_shaders(const struct tw_gl *gl, const struct tw_log *log, const GLuint *shaders,
                           int n, bool *out_of_memory)
{
    GLuint p = gl->CreateProgram();
    for (int k = 0; k < n; k++)
        gl->AttachShader(p, shaders[k]);
    gl->LinkProgram(p);
    GLint ok = 0;
    gl->GetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        char msg[1024] = "";
        gl->GetProgramInfoLog(p, sizeof(msg), NULL, msg);
        report(gl, log, out_of_memory, "linking a shader program",
               "a shader program does not link", msg);
        gl->DeleteProgram(p);
        p = 0;
    }
    for (int k = 0; k < n; k++)
        gl->DeleteShader(shaders[k]);
    return p;
}

GLuint tw_programs_link(const struct tw_gl *gl, const struct tw_log *log, const char *vs_src,
                        const char *gs_src, const char *fs_src, bool *out_of_memory)
{
    GLuint sh[3];
    int n = 0;
    sh[n] = compile(gl, log, GL_VERTEX_SHADER, vs_src, out_of_memory);
    n += sh[n] != 0;
    if (gs_src) {
        sh[n] = compile(gl, log, GL_GEOMETRY_SHADER, gs_src, out_of_memory);
        n += sh[n] != 0;
    }
    sh[n] = compile(gl, log, GL_FRAGMENT_SHADER, fs_src, out_of_memory);
    n += sh[n] != 0;
    if (n == (gs_src ? 3 : 2))
        return link_shaders(gl, log, sh, n, out_of_memory);
    for (int k = 0; k < n; k++)
        gl->DeleteShader(sh[k]);
    return 0;
}

GLuint tw_programs_link_compute(const struct tw_gl *gl, const struct tw_log *log,
                                const char *cs_src, bool *out_of_memory)
{
    const GLuint cs = compile(gl, log, GL_COMPUTE_SHADER, cs_src, out_of_memory);
    return cs ? link_shaders(gl, log, &cs, 1, out_of_memory) : 0;
}

int tw_programs_init(struct tw_programs *p, const struct tw_gl *gl, const struct tw_log *log)
{
    memset(p, 0, sizeof(*p));
    bool out_of_memory = false;
    p->scene.program = tw_programs_link(gl, log, scene_vs, NULL, scene_fs, &out_of_memory);
    p->query.program = tw_programs_link(gl, log, query_vs, NULL, box_fs, &out_of_memory);
    p->id.program = tw_programs_link(gl, log, scene_vs, NULL, id_fs, &out_of_memory);
    p->line.program = tw_programs_link(gl, log, box_vs, line_gs, color_fs, &out_of_memory);
    p->fill.program = tw_programs_link(gl, log, box_vs, NULL, color_fs, &out_of_memory);
    if (!p->scene.program || !p->query.program || !p->id.program || !p->line.program ||
        !p->fill.program)
        return out_of_memory ? TW_ERR_NOMEM : TW_ERR_GL;
    p->scene.view_proj = gl->GetUniformLocation(p->scene.program, "u_view_proj");
    p->scene.eye = gl->GetUniformLocation(p->scene.program, "u_eye");
    p->scene.fog = gl->GetUniformLocation(p->scene.program, "u_fog");
    p->id.view_proj = gl->GetUniformLocation(p->id.program, "u_view_proj");
    p->line.view_proj = gl->GetUniformLocation(p->line.program, "u_view_proj");
    p->line.min = gl->GetUniformLocation(p->line.program, "u_min");
    p->line.max = gl->GetUniformLocation(p->line.program, "u_max");
    p->line.color = gl->GetUniformLocation(p->line.program, "u_color");
    p->line.viewport = gl->GetUniformLocation(p->line.program, "u_viewport");
    p->fill.view_proj = gl->GetUniformLocation(p->fill.program, "u_view_proj");
    p->fill.min = gl->GetUniformLocation(p->fill.program, "u_min");
    p->fill.max = gl->GetUniformLocation(p->fill.program, "u_max");
    p->fill.color = gl->GetUniformLocation(p->fill.program, "u_color");
    p->query.view_proj = gl->GetUniformLocation(p->query.program, "u_view_proj");
    return TW_OK;
}

void tw_programs_finish(struct tw_programs *p, const struct tw_gl *gl)
{
    if (p->id.program)
        gl->DeleteProgram(p->id.program);
    if (p->scene.program)
        gl->DeleteProgram(p->scene.program);
    if (p->query.program)
        gl->DeleteProgram(p->query.program);
    if (p->line.program)
        gl->DeleteProgram(p->line.program);
    if (p->fill.program)
        gl->DeleteProgram(p->fill.program);
    memset(p, 0, sizeof(*p));
}

/*
 * A table of the OpenGL entry points the runtime and the viewer use, loaded
 * through a context's get-proc function. The runtime never links gl*
 * symbols directly, so the OSMesa (headless) and libGL (window) paths
 * cannot collide.
 */
#ifndef TW_RUNTIME_GL_H
#define TW_RUNTIME_GL_H

#include <GL/glcorearb.h>

#include "tileworld/runtime.h"

#define TW_GL_FUNCTIONS(X) \
    X(PFNGLGETERRORPROC, GetError) \
    X(PFNGLGETSTRINGPROC, GetString) \
    X(PFNGLGETINTEGERVPROC, GetIntegerv) \
    X(PFNGLCLEARPROC, Clear) \
    X(PFNGLCLEARCOLORPROC, ClearColor) \
    X(PFNGLCLEARDEPTHPROC, ClearDepth) \
    X(PFNGLVIEWPORTPROC, Viewport) \
    X(PFNGLSCISSORPROC, Scissor) \
    X(PFNGLENABLEPROC, Enable) \
    X(PFNGLDISABLEPROC, Disable) \
    X(PFNGLDEPTHFUNCPROC, DepthFunc) \
    X(PFNGLDEPTHMASKPROC, DepthMask) \
    X(PFNGLCOLORMASKPROC, ColorMask) \
    X(PFNGLCULLFACEPROC, CullFace) \
    X(PFNGLFINISHPROC, Finish) \
    X(PFNGLFLUSHPROC, Flush) \
    X(PFNGLREADPIXELSPROC, ReadPixels) \
    X(PFNGLPIXELSTOREIPROC, PixelStorei) \
    X(PFNGLGENBUFFERSPROC, GenBuffers) \
    X(PFNGLDELETEBUFFERSPROC, DeleteBuffers) \
    X(PFNGLBINDBUFFERPROC, BindBuffer) \
    X(PFNGLBUFFERDATAPROC, BufferData) \
    X(PFNGLBUFFERSUBDATAPROC, BufferSubData) \
    X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays) \
    X(PFNGLISVERTEXARRAYPROC, IsVertexArray) \
    X(PFNGLDELETEVERTEXARRAYSPROC, DeleteVertexArrays) \
    X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray) \
    X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray) \
    X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer) \
    X(PFNGLCREATESHADERPROC, CreateShader) \
    X(PFNGLSHADERSOURCEPROC, ShaderSource) \
    X(PFNGLCOMPILESHADERPROC, CompileShader) \
    X(PFNGLGETSHADERIVPROC, GetShaderiv) \
    X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog) \
    X(PFNGLDELETESHADERPROC, DeleteShader) \
    X(PFNGLCREATEPROGRAMPROC, CreateProgram) \
    X(PFNGLATTACHSHADERPROC, AttachShader) \
    X(PFNGLLINKPROGRAMPROC, LinkProgram) \
    X(PFNGLGETPROGRAMIVPROC, GetProgramiv) \
    X(PFNGLGETPROGRAMINFOLOGPROC, GetProgramInfoLog) \
    X(PFNGLDELETEPROGRAMPROC, DeleteProgram) \
    X(PFNGLUSEPROGRAMPROC, UseProgram) \
    X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation) \
    X(PFNGLUNIFORM1UIPROC, Uniform1ui) \
    X(PFNGLUNIFORM2FVPROC, Uniform2fv) \
    X(PFNGLUNIFORM3FVPROC, Uniform3fv) \
    X(PFNGLUNIFORM4FVPROC, Uniform4fv) \
    X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv) \
    X(PFNGLDRAWARRAYSPROC, DrawArrays) \
    X(PFNGLDRAWELEMENTSPROC, DrawElements) \
    X(PFNGLDRAWELEMENTSBASEVERTEXPROC, DrawElementsBaseVertex) \
    X(PFNGLDRAWELEMENTSINSTANCEDPROC, DrawElementsInstanced) \
    X(PFNGLMULTIDRAWELEMENTSBASEVERTEXPROC, MultiDrawElementsBaseVertex) \
    X(PFNGLVERTEXATTRIBDIVISORPROC, VertexAttribDivisor) \
    X(PFNGLGENQUERIESPROC, GenQueries) \
    X(PFNGLDELETEQUERIESPROC, DeleteQueries) \
    X(PFNGLBEGINQUERYPROC, BeginQuery) \
    X(PFNGLENDQUERYPROC, EndQuery) \
    X(PFNGLGETQUERYOBJECTUIVPROC, GetQueryObjectuiv) \
    X(PFNGLGETQUERYIVPROC, GetQueryiv) \
    X(PFNGLQUERYCOUNTERPROC, QueryCounter) \
    X(PFNGLGETQUERYOBJECTUI64VPROC, GetQueryObjectui64v) \
    X(PFNGLBEGINCONDITIONALRENDERPROC, BeginConditionalRender) \
    X(PFNGLENDCONDITIONALRENDERPROC, EndConditionalRender) \
    X(PFNGLGENFRAMEBUFFERSPROC, GenFramebuffers) \
    X(PFNGLDELETEFRAMEBUFFERSPROC, DeleteFramebuffers) \
    X(PFNGLBINDFRAMEBUFFERPROC, BindFramebuffer) \
    X(PFNGLFRAMEBUFFERRENDERBUFFERPROC, FramebufferRenderbuffer) \
    X(PFNGLCHECKFRAMEBUFFERSTATUSPROC, CheckFramebufferStatus) \
    X(PFNGLGENRENDERBUFFERSPROC, GenRenderbuffers) \
    X(PFNGLDELETERENDERBUFFERSPROC, DeleteRenderbuffers) \
    X(PFNGLBINDRENDERBUFFERPROC, BindRenderbuffer) \
    X(PFNGLRENDERBUFFERSTORAGEPROC, RenderbufferStorage) \
    X(PFNGLDRAWBUFFERSPROC, DrawBuffers) \
    X(PFNGLREADBUFFERPROC, ReadBuffer) \
    X(PFNGLCLEARBUFFERUIVPROC, ClearBufferuiv) \
    X(PFNGLCLEARBUFFERFVPROC, ClearBufferfv) \
    X(PFNGLGETSTRINGIPROC, GetStringi) \
    X(PFNGLBLITFRAMEBUFFERPROC, BlitFramebuffer) \
    X(PFNGLBLENDFUNCPROC, BlendFunc) \
    X(PFNGLBLENDFUNCSEPARATEPROC, BlendFuncSeparate) \
    X(PFNGLGETBOOLEANVPROC, GetBooleanv) \
    X(PFNGLGETFLOATVPROC, GetFloatv) \
    X(PFNGLGETDOUBLEVPROC, GetDoublev) \
    X(PFNGLISENABLEDPROC, IsEnabled) \
    X(PFNGLFRONTFACEPROC, FrontFace) \
    X(PFNGLPOLYGONMODEPROC, PolygonMode) \
    X(PFNGLDEPTHRANGEPROC, DepthRange)

/* Entry points the renderer can do without (NULL when the loader has none):
 * glClipControl is core only since 4.5 (ARB_clip_control before). A loader
 * may also hand out a pointer that the context cannot use, so the renderer
 * checks the version or the extension before calling it. */
#define TW_GL_OPTIONAL_FUNCTIONS(X) \
    X(PFNGLCLIPCONTROLPROC, ClipControl) \
    X(PFNGLMULTIDRAWELEMENTSINDIRECTPROC, MultiDrawElementsIndirect) \
    X(PFNGLDISPATCHCOMPUTEPROC, DispatchCompute) \
    X(PFNGLMEMORYBARRIERPROC, MemoryBarrier) \
    X(PFNGLBINDBUFFERRANGEPROC, BindBufferRange) \
    X(PFNGLBINDBUFFERBASEPROC, BindBufferBase) \
    X(PFNGLTEXSTORAGE2DPROC, TexStorage2D) \
    X(PFNGLFENCESYNCPROC, FenceSync) \
    X(PFNGLCLIENTWAITSYNCPROC, ClientWaitSync) \
    X(PFNGLDELETESYNCPROC, DeleteSync) \
    X(PFNGLISSYNCPROC, IsSync) \
    X(PFNGLGETBUFFERSUBDATAPROC, GetBufferSubData) \
    X(PFNGLCOPYBUFFERSUBDATAPROC, CopyBufferSubData) \
    X(PFNGLCLEARBUFFERDATAPROC, ClearBufferData) \
    X(PFNGLGETINTEGERI_VPROC, GetIntegeri_v) \
    X(PFNGLGETINTEGER64I_VPROC, GetInteger64i_v) \
    X(PFNGLUNIFORM1IPROC, Uniform1i) \
    X(PFNGLUNIFORM1FPROC, Uniform1f) \
    X(PFNGLUNIFORM2IPROC, Uniform2i) \
    X(PFNGLUNIFORM1IVPROC, Uniform1iv) \
    X(PFNGLGENTEXTURESPROC, GenTextures) \
    X(PFNGLDELETETEXTURESPROC, DeleteTextures) \
    X(PFNGLBINDTEXTUREPROC, BindTexture) \
    X(PFNGLACTIVETEXTUREPROC, ActiveTexture) \
    X(PFNGLTEXPARAMETERIPROC, TexParameteri) \
    X(PFNGLFRAMEBUFFERTEXTURE2DPROC, FramebufferTexture2D)

struct tw_gl {
#define TW_GL_MEMBER(type, name) type name;
    TW_GL_FUNCTIONS(TW_GL_MEMBER)
    TW_GL_OPTIONAL_FUNCTIONS(TW_GL_MEMBER)
#undef TW_GL_MEMBER
};

/* The host's GL state that the world changes, saved on entry into the
 * library and restored on exit (runtime.h, tw_world_frame). */
/* What the compute passes change (saved only where they run): the active
 * texture unit and unit 0's 2D texture, the copy buffers, the generic and
 * the first six indexed shader storage bindings. */
#define TW_GL_COMPUTE_SSBOS 6
struct tw_gl_compute_state {
    GLint active_texture, texture, copy_read, copy_write;
    GLint ssbo, ssbo_name[TW_GL_COMPUTE_SSBOS];
    GLint64 ssbo_start[TW_GL_COMPUTE_SSBOS], ssbo_size[TW_GL_COMPUTE_SSBOS];
};
void tw_gl_compute_state_enter(const struct tw_gl *gl, struct tw_gl_compute_state *s);
void tw_gl_compute_state_leave(const struct tw_gl *gl, const struct tw_gl_compute_state *s);

struct tw_gl_state {
    GLint draw_fbo, read_fbo, renderbuffer, program, vertex_array, array_buffer;
    GLint pixel_pack_buffer, pixel_unpack_buffer;
    GLint viewport[4];
    GLint depth_func, cull_face_mode, front_face, polygon_mode[2];
    GLint blend_src_rgb, blend_dst_rgb, blend_src_alpha, blend_dst_alpha;
    GLint pack_alignment, pack_row_length, pack_skip_rows, pack_skip_pixels;
    GLint clip_origin, clip_depth_mode;
    GLboolean depth_mask, color_mask[4];
    GLfloat clear_color[4];
    GLdouble clear_depth, depth_range[2];
    uint32_t enabled;       /* bit k: capability k of tw_gl_state_capabilities was enabled */
};

/* Saves the state of s that the library changes, then sets the state the
 * library relies on (no scissor, stencil, blending, polygon offset,
 * rasteriser discard, sRGB conversion, primitive restart, logic op or depth
 * clamp; counter-clockwise front faces, filled polygons, depth range [0, 1],
 * no pixel buffers bound, plain pack layout). has_clip_control: the
 * context's glClipControl may be called. */
void tw_gl_state_enter(const struct tw_gl *gl, bool has_clip_control, struct tw_gl_state *s);
/* Sets the state tw_gl_state_enter() sets, without saving anything: after
 * a host's callback that may have changed it. */
void tw_gl_state_reset(const struct tw_gl *gl);
/* Restores what tw_gl_state_enter() saved. */
void tw_gl_state_leave(const struct tw_gl *gl, bool has_clip_control, const struct tw_gl_state *s);

/* Loads every entry point; names the first missing required one in the log
 * and returns TW_ERR_GL if any is missing. Optional ones may stay NULL. */
int tw_gl_load(struct tw_gl *gl, tw_gl_get_proc_fn get_proc, const struct tw_log *log);

#endif

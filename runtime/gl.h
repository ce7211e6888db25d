/*
 * A table of the OpenGL entry points the runtime uses, loaded through a
 * context's get-proc function. The runtime never links gl* symbols directly,
 * so the OSMesa (headless) and libGL (window) paths cannot collide.
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
    X(PFNGLDRAWELEMENTSPROC, DrawElements) \
    X(PFNGLDRAWELEMENTSBASEVERTEXPROC, DrawElementsBaseVertex) \
    X(PFNGLGENQUERIESPROC, GenQueries) \
    X(PFNGLDELETEQUERIESPROC, DeleteQueries) \
    X(PFNGLBEGINQUERYPROC, BeginQuery) \
    X(PFNGLENDQUERYPROC, EndQuery) \
    X(PFNGLGETQUERYOBJECTUIVPROC, GetQueryObjectuiv) \
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
    X(PFNGLBLENDFUNCPROC, BlendFunc)

/* Entry points the renderer can do without (NULL when the loader has none):
 * glClipControl is core only since 4.5 (ARB_clip_control before). A loader
 * may also hand out a pointer that the context cannot use, so the renderer
 * checks the version or the extension before calling it. */
#define TW_GL_OPTIONAL_FUNCTIONS(X) \
    X(PFNGLCLIPCONTROLPROC, ClipControl)

struct tw_gl {
#define TW_GL_MEMBER(type, name) type name;
    TW_GL_FUNCTIONS(TW_GL_MEMBER)
    TW_GL_OPTIONAL_FUNCTIONS(TW_GL_MEMBER)
#undef TW_GL_MEMBER
};

/* Loads every entry point; names the first missing required one in the log
 * and returns TW_ERR_GL if any is missing. Optional ones may stay NULL. */
int tw_gl_load(struct tw_gl *gl, tw_gl_get_proc_fn get_proc, const struct tw_log *log);

#endif

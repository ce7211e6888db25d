/* Output files written whole or not at all (outfile.h). */
#include "tools/outfile.h"

#include <errno.h>
#include <fcntl.h>
#include <png.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tileworld/tiles.h"

bool tw_outfile_tmp_name(const char *path, char *out, size_t size)
{
    const char *slash = strrchr(path, '/');
    const int dir_len = slash ? (int)(slash - path + 1) : 0;
    const int n = snprintf(out, size, "%.*s.%s.tmp", dir_len, path, path + dir_len);
    return n > 0 && (size_t)n < size;
}

static int open_tmp(struct tw_outfile *o, const char *path, bool unique, char *err,
                    size_t err_size)
{
    memset(o, 0, sizeof(*o));
    const int n = snprintf(o->path, sizeof(o->path), "%s", path);
    bool fits = n >= 0 && (size_t)n < sizeof(o->path) &&
                tw_outfile_tmp_name(path, o->tmp, sizeof(o->tmp));
    if (fits && unique) {
        const size_t used = strlen(o->tmp);
        const int m = snprintf(o->tmp + used, sizeof(o->tmp) - used, ".%ld", (long)getpid());
        fits = m > 0 && (size_t)m < sizeof(o->tmp) - used;
    }
    if (!fits) {
        snprintf(err, err_size, "%s: cannot write: %s", path, strerror(ENAMETOOLONG));
        return TW_ERR_IO;
    }
    /* A new file, not whatever a name left behind points to. */
    if (unlink(o->tmp) != 0 && errno != ENOENT) {
        snprintf(err, err_size, "%s: cannot write: %s", o->tmp, strerror(errno));
        return TW_ERR_IO;
    }
    const int fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    o->f = fd < 0 ? NULL : fdopen(fd, "w");
    if (!o->f) {
        const int e = errno;
        if (fd >= 0) {
            close(fd);
            unlink(o->tmp);
        }
        snprintf(err, err_size, "%s: cannot write: %s", path, strerror(e));
        return TW_ERR_IO;
    }
    return TW_OK;
}

int tw_outfile_open(struct tw_outfile *o, const char *path, char *err, size_t err_size)
{
    return open_tmp(o, path, false, err, err_size);
}

int tw_outfile_open_unique(struct tw_outfile *o, const char *path, char *err, size_t err_size)
{
    return open_tmp(o, path, true, err, err_size);
}

static bool failed(struct tw_outfile *o)
{
    if (!o->error)
        o->error = errno ? errno : EIO;
    return false;
}

bool tw_outfile_printf(struct tw_outfile *o, const char *fmt, ...)
{
    if (o->error || !o->f)
        return false;
    va_list ap;
    va_start(ap, fmt);
    errno = 0;
    const int n = vfprintf(o->f, fmt, ap);
    va_end(ap);
    return n < 0 ? failed(o) : true;
}

bool tw_outfile_write(struct tw_outfile *o, const void *data, size_t size)
{
    if (o->error || !o->f)
        return false;
    errno = 0;
    return fwrite(data, 1, size, o->f) != size ? failed(o) : true;
}

int tw_outfile_report(const struct tw_outfile *o, char *err, size_t err_size)
{
    snprintf(err, err_size, "%s: cannot write: %s", o->path, strerror(o->error ? o->error : EIO));
    return TW_ERR_IO;
}

int tw_outfile_commit(struct tw_outfile *o, char *err, size_t err_size)
{
    if (!o->f)
        return tw_outfile_report(o, err, err_size);
    errno = 0;
    if (!o->error && (fflush(o->f) != 0 || ferror(o->f)))
        failed(o);
    errno = 0;
    if (fclose(o->f) != 0 && !o->error)
        failed(o);
    o->f = NULL;
    errno = 0;
    if (!o->error && rename(o->tmp, o->path) != 0)
        failed(o);
    if (o->error) {
        unlink(o->tmp);
        return tw_outfile_report(o, err, err_size);
    }
    return TW_OK;
}

void tw_outfile_discard(struct tw_outfile *o)
{
    if (!o->f)
        return;
    fclose(o->f);
    o->f = NULL;
    unlink(o->tmp);
}

int tw_outfile_write_all(const char *path, const void *data, size_t size, char *err,
                         size_t err_size)
{
    struct tw_outfile o;
    int rc = tw_outfile_open(&o, path, err, err_size);
    if (rc)
        return rc;
    tw_outfile_write(&o, data, size);
    return tw_outfile_commit(&o, err, err_size);
}

/* ---- PNG: encoded in memory, then written whole -------------------------------- */

struct png_buffer {
    uint8_t *data;
    size_t size, cap;
    bool nomem;
};

static void png_buffer_write(png_structp png, png_bytep data, png_size_t size)
{
    struct png_buffer *b = png_get_io_ptr(png);
    if (b->size + size > b->cap) {
        size_t cap = b->cap ? b->cap : 65536;
        while (cap < b->size + size)
            cap *= 2;
        uint8_t *p = realloc(b->data, cap);
        if (!p) {
            b->nomem = true;
            png_error(png, "out of memory");
        }
        b->data = p;
        b->cap = cap;
    }
    memcpy(b->data + b->size, data, size);
    b->size += size;
}

static void png_buffer_flush(png_structp png)
{
    (void)png;
}

/* libpng's default handlers print on stderr: the caller prints one line. */
static void png_quiet_error(png_structp png, png_const_charp msg)
{
    (void)msg;
    png_longjmp(png, 1);
}

static void png_quiet_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

int tw_outfile_write_png(const char *path, const uint8_t *rgb, uint32_t width, uint32_t height,
                         char *err, size_t err_size)
{
    /* On the heap: what changes between setjmp and longjmp must not be a
     * local of this frame. */
    struct png_buffer *buf = calloc(1, sizeof(*buf));
    png_structp png = buf ? png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, png_quiet_error,
                                                    png_quiet_warning)
                          : NULL;
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        png_destroy_write_struct(&png, &info);
        free(buf);
        snprintf(err, err_size, "%s: out of memory for libpng", path);
        return TW_ERR_NOMEM;
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        snprintf(err, err_size, "%s: %s", path,
                 buf->nomem ? "out of memory for the image" : "libpng failed to encode the image");
        free(buf->data);
        free(buf);
        return TW_ERR_NOMEM;
    }
    png_set_write_fn(png, buf, png_buffer_write, png_buffer_flush);
    png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (uint32_t y = 0; y < height; y++)
        png_write_row(png, (png_const_bytep)(rgb + (size_t)y * width * 3));
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    const int rc = tw_outfile_write_all(path, buf->data, buf->size, err, err_size);
    free(buf->data);
    free(buf);
    return rc;
}

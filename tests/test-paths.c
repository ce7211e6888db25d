/* Unit tests of the camera-path CSV reader (runtime/paths.c):
 * every bad row is refused at load with one line "FILE:LINE: reason" that
 * says what is wrong with which field; special files are refused, never
 * waited on; text from the file reaches messages escaped. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tileworld/runtime.h"
#include "tests/check.h"
#include "tests/watchdog.h"

static char dir[64];

static char *join(const char *name)
{
    static char path[256];
    snprintf(path, sizeof(path), "%s/%s", dir, name);
    return path;
}

static void write_file(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (f) {
        fwrite(data, 1, n, f);
        fclose(f);
    }
}

/* Parses text (as name) and expects a refusal whose message is exactly
 * "name:want". */
static void expect_refused(const char *text, size_t n, const char *want)
{
    struct tw_path p;
    char err[512];
    const int rc = tw_path_parse_csv(text, n, "p.csv", 0, 80, 80, &p, err, sizeof(err));
    char full[512];
    snprintf(full, sizeof(full), "p.csv:%s", want);
    if (rc == 0 || strcmp(err, full) != 0)
        fprintf(stderr, "  got \"%s\"\n  expected \"%s\"\n", err, full);
    CHECK(rc != 0 && strcmp(err, full) == 0);
    CHECK(p.keys == NULL && p.count == 0);
}

#define HEADER "cell_i,cell_j,x,y,z,yaw,pitch\n"
#define REFUSED(body, want) expect_refused(HEADER body, sizeof(HEADER body) - 1, want)

static void test_messages(void)
{
    /* The audit's examples. */
    REFUSED("0,0,1,1.7,1,1e300,0\n",
            "2: field 6 (yaw) \"1e300\" is outside [-1e+06, 1e+06] degrees");
    expect_refused(HEADER "0,0,1,1.\0007,1,0,0\n", sizeof(HEADER "0,0,1,1.\0007,1,0,0\n") - 1,
                   "2: a NUL byte at column 9: not a text file");
    REFUSED("0x10,0,1,1.7,1,0,0\n",
            "2: field 1 (cell_i) \"0x10\" is not a decimal integer (hexadecimal is not accepted)");
    /* Every field, every reason. */
    REFUSED("0,0,1,1.7,1,0\n",
            "2: expected 7 comma-separated fields (cell_i,cell_j,x,y,z,yaw,pitch), found 6");
    REFUSED("0,0,1,1.7,1,0,0,9\n",
            "2: expected 7 comma-separated fields (cell_i,cell_j,x,y,z,yaw,pitch), found 8");
    REFUSED("0,,1,1.7,1,0,0\n", "2: field 2 (cell_j) is empty");
    REFUSED("0,1.5,1,1.7,1,0,0\n",
            "2: field 2 (cell_j) \"1.5\" is not a decimal integer (a cell is a whole number)");
    REFUSED("99999999999999999999,0,1,1.7,1,0,0\n",
            "2: field 1 (cell_i) \"99999999999999999999\" is beyond the 64-bit range of a cell");
    REFUSED("-9223372036854775809,0,1,1.7,1,0,0\n",
            "2: field 1 (cell_i) \"-9223372036854775809\" is beyond the 64-bit range of a cell");
    REFUSED("0,0,abc,1.7,1,0,0\n", "2: field 3 (x) \"abc\" is not a decimal number");
    REFUSED("0,0,nan,1.7,1,0,0\n", "2: field 3 (x) \"nan\" is not a decimal number");
    REFUSED("0,0,0x1p3,1.7,1,0,0\n", "2: field 3 (x) \"0x1p3\" is not a decimal number");
    REFUSED("0,0,1,1e400,1,0,0\n",
            "2: field 4 (y) \"1e400\" is outside [-100000, 100000] metres above the ground");
    REFUSED("0,0,1,-1e30,1,0,0\n",
            "2: field 4 (y) \"-1e30\" is outside [-100000, 100000] metres above the ground");
    REFUSED("0,0,1,1.7,2e7,0,0\n",
            "2: field 5 (z) \"2e7\" is outside [-1e+07, 1e+07] metres from the cell's origin");
    REFUSED("0,0,1,1.7,1,0,89.9\n", "2: field 7 (pitch) \"89.9\" is outside (-89.9, 89.9) degrees");
    REFUSED("0,0,1,1.7,1,0,1 2\n", "2: field 7 (pitch) \"1 2\" is not a decimal number");
    REFUSED("9223372036854775807,0,1e6,1.7,1,0,0\n",
            "2: the position overflows the grid (cell plus offset beyond 64 bits)");
    /* Text from the file is escaped and cut. */
    REFUSED("\x1b[2J,0,1,1.7,1,0,0\n",
            "2: field 1 (cell_i) \"\\x1b[2J\" is not a decimal integer");
    REFUSED("0,0,1,1.7,1,0,0\n1,1,1,1.7,1,0,0123456789012345678901234567890123456789\n",
            "3: field 7 (pitch) \"01234567890123456789012345678901...\" is outside (-89.9, "
            "89.9) degrees");
    /* Lines, header, emptiness. */
    char long_line[1100];
    memset(long_line, ' ', sizeof(long_line));
    memcpy(long_line, HEADER, sizeof(HEADER) - 1);
    long_line[sizeof(long_line) - 1] = '\n';
    expect_refused(long_line, sizeof(long_line), "2: line longer than 1022 characters");
    expect_refused("x,y\n", 4, "1: expected the header cell_i,cell_j,x,y,z,yaw,pitch");
    struct tw_path p;
    char err[512];
    CHECK(tw_path_parse_csv("", 0, "p.csv", 0, 80, 80, &p, err, sizeof(err)) == TW_ERR_FORMAT &&
          strcmp(err, "p.csv: empty file (expected a header line)") == 0);
    CHECK(tw_path_parse_csv(HEADER, sizeof(HEADER) - 1, "p.csv", 0, 80, 80, &p, err,
                            sizeof(err)) == TW_ERR_FORMAT &&
          strcmp(err, "p.csv: no camera rows after the header") == 0);
    CHECK(tw_path_parse_csv(HEADER "0,0,1,1,1,0,0\n", sizeof(HEADER "0,0,1,1,1,0,0\n") - 1,
                            "p.csv", 3, 80, 80, &p, err, sizeof(err)) == TW_ERR_FORMAT &&
          strcmp(err, "p.csv: 3 frames asked for but the file has 1 rows") == 0);
}

static void test_good_file(void)
{
    /* A byte order mark, CRLF, spaces, a blank line; offsets in double. */
    static const char text[] = "\xef\xbb\xbf" "cell_i,cell_j,x,y,z,yaw,pitch\r\n"
                               " 3 , -4 , 9999999.5 , 1.7 , -0.25 , 725 , -10 \r\n"
                               "\r\n"
                               "-9223372036854775808,9223372036854775807,0,0,79.75,-90,89.8\n"
                               "0,0,1,2,3,4,5";
    struct tw_path p;
    char err[512] = "";
    const int rc = tw_path_parse_csv(text, sizeof(text) - 1, "dir/good.csv", 0, 80, 80, &p, err,
                                     sizeof(err));
    CHECK(rc == 0);
    if (rc) {
        fprintf(stderr, "  %s\n", err);
        return;
    }
    CHECK(p.count == 3 && strcmp(p.name, "good.csv") == 0);
    /* 9999999.5 = 124999 * 80 + 79.5: the float the old reader went
     * through rounded it to 1e7, a cell further on. */
    CHECK(p.keys[0].pos.cell.i == 3 + 124999 && p.keys[0].pos.local[0] == 79.5f);
    CHECK(p.keys[0].pos.cell.j == -5 && p.keys[0].pos.local[2] == 79.75f);
    CHECK(p.keys[0].yaw == 5.0f && p.keys[0].pitch == -10.0f);
    CHECK(p.keys[1].pos.cell.i == INT64_MIN && p.keys[1].pos.cell.j == INT64_MAX);
    CHECK(p.keys[1].yaw == -90.0f);
    CHECK(p.keys[2].pos.local[1] == 2.0f && p.keys[2].yaw == 4.0f);
    tw_path_finish(&p);
    /* frames keeps the first rows. */
    CHECK(tw_path_parse_csv(text, sizeof(text) - 1, "good.csv", 2, 80, 80, &p, err,
                            sizeof(err)) == 0 && p.count == 2);
    tw_path_finish(&p);
}

static void test_files(void)
{
    snprintf(dir, sizeof(dir), "/tmp/tw-test-paths-XXXXXX");
    CHECK(mkdtemp(dir) != NULL);
    struct tw_path p;
    char err[512];
    static const char good[] = HEADER "0,0,1,1.7,1,0,0\n";
    write_file(join("good.csv"), good, sizeof(good) - 1);
    CHECK(tw_path_load_csv(join("good.csv"), 0, 80, 80, &p, err, sizeof(err)) == 0 &&
          p.count == 1);
    tw_path_finish(&p);

    /* A FIFO nobody writes to: refused at once, never waited on. */
    char fifo[256];
    snprintf(fifo, sizeof(fifo), "%s", join("fifo.csv"));
    CHECK(mkfifo(fifo, 0600) == 0);
    watchdog_arm(20, "test-paths: blocked on a special file\n");
    int rc = tw_path_load_csv(fifo, 0, 80, 80, &p, err, sizeof(err));
    watchdog_disarm();
    char want[512];
    snprintf(want, sizeof(want), "%s: is not a regular file (a FIFO)", fifo);
    CHECK(rc == TW_ERR_IO && strcmp(err, want) == 0);
    unlink(fifo);
    rc = tw_path_load_csv(dir, 0, 80, 80, &p, err, sizeof(err));
    CHECK(rc == TW_ERR_IO && strstr(err, "is not a regular file (a folder)"));
    rc = tw_path_load_csv("/dev/null", 0, 80, 80, &p, err, sizeof(err));
    CHECK(rc == TW_ERR_IO && strcmp(err, "/dev/null: is not a regular file (a device)") == 0);
    rc = tw_path_load_csv(join("missing.csv"), 0, 80, 80, &p, err, sizeof(err));
    CHECK(rc == TW_ERR_IO && strstr(err, "missing.csv: no such file"));

    /* A file name with an escape sequence is shown escaped. */
    char evil[256];
    snprintf(evil, sizeof(evil), "%s", join("a\x1b[2J\nb.csv"));
    static const char bad[] = HEADER "0,0,1,1.7,1,0,99\n";
    write_file(evil, bad, sizeof(bad) - 1);
    rc = tw_path_load_csv(evil, 0, 80, 80, &p, err, sizeof(err));
    CHECK(rc == TW_ERR_FORMAT && strstr(err, "a\\x1b[2J\\nb.csv:2: field 7 (pitch)") &&
          !strchr(err, '\x1b') && !strchr(err, '\n'));
    unlink(evil);
    unlink(join("good.csv"));
    rmdir(dir);
}

/* Bytes this process has read through read() so far (Linux's
 * /proc/self/io), or -1 where that is not known. */
static long long bytes_read_so_far(void)
{
    FILE *f = fopen("/proc/self/io", "r");
    long long n = -1;
    char line[128];
    while (f && fgets(line, sizeof(line), f))
        if (sscanf(line, "rchar: %lld", &n) == 1)
            break;
    if (f)
        fclose(f);
    return n;
}

/* A file of text followed by zeros up to size bytes (a sparse file: no
 * disk is written). */
static void sparse_file(const char *path, const char *text, off_t size)
{
    write_file(path, text, strlen(text));
    CHECK(truncate(path, size) == 0);
}

/* The file is read a block at a time: a bad row, or the rows asked for, end
 * the reading there, and a file beyond the byte limit is refused before it
 * is read. Counted in bytes read, not in time. */
static void test_streaming(void)
{
    CHECK(mkdtemp(dir) != NULL);
    struct tw_path p;
    char err[512];
    char path[256];

    /* 900 MiB whose second line is bad (zeros follow: NUL bytes). */
    snprintf(path, sizeof(path), "%s", join("bad-early.csv"));
    sparse_file(path, HEADER "0,0,1,1.7,1,0,99\n", (off_t)900 << 20);
    long long before = bytes_read_so_far();
    int rc = tw_path_load_csv(path, 0, 80, 80, &p, err, sizeof(err));
    long long read_bytes = bytes_read_so_far() - before;
    CHECK_MSG(rc == TW_ERR_FORMAT && strstr(err, "bad-early.csv:2: field 7 (pitch)"),
              "bad row early: %s", err);
    if (before >= 0)
        CHECK_MSG(read_bytes < (1 << 20), "bad row early: read %lld bytes of 900 MiB", read_bytes);
    unlink(path);

    /* The frames asked for are read, nothing after them. */
    snprintf(path, sizeof(path), "%s", join("frames.csv"));
    sparse_file(path, HEADER "0,0,1,1.7,1,0,0\n1,0,1,1.7,1,0,0\n2,0,1,1.7,1,0,0\n",
                (off_t)900 << 20);
    before = bytes_read_so_far();
    rc = tw_path_load_csv(path, 3, 80, 80, &p, err, sizeof(err));
    read_bytes = bytes_read_so_far() - before;
    CHECK_MSG(rc == 0 && p.count == 3 && p.keys[2].pos.cell.i == 2, "3 frames: %s", err);
    if (before >= 0)
        CHECK_MSG(read_bytes < (1 << 20), "3 frames: read %lld bytes of 900 MiB", read_bytes);
    tw_path_finish(&p);
    unlink(path);

    /* Beyond the byte limit: refused by its size, before it is read. */
    snprintf(path, sizeof(path), "%s", join("huge.csv"));
    sparse_file(path, HEADER, (off_t)TW_PATH_MAX_CSV_BYTES + 1);
    before = bytes_read_so_far();
    rc = tw_path_load_csv(path, 0, 80, 80, &p, err, sizeof(err));
    read_bytes = bytes_read_so_far() - before;
    CHECK_MSG(rc == TW_ERR_LIMIT && strstr(err, "huge.csv: is 1073741825 bytes, more than the "
                                               "limit of 1073741824"),
              "huge file: %s", err);
    if (before >= 0)
        CHECK_MSG(read_bytes < 4096, "huge file: read %lld bytes", read_bytes);
    unlink(path);

    /* Lines across the reader's blocks (64 KiB) read as from memory, and a
     * long line across one is refused on its own line. */
    size_t cap = 400000, n = 0;
    char *text = malloc(cap);
    CHECK(text != NULL);
    n += (size_t)snprintf(text, cap, "\xef\xbb\xbf%s", HEADER);
    for (int k = 0; n + 64 < cap && k < 9000; k++)
        n += (size_t)snprintf(text + n, cap - n, "%d,%d,%d.5,1.7,%d.25,%d,%d\r\n", k, -k, k % 80,
                              k % 79, k % 360, k % 80 - 40);
    snprintf(path, sizeof(path), "%s", join("long.csv"));
    write_file(path, text, n);
    struct tw_path q;
    CHECK(tw_path_parse_csv(text, n, path, 0, 80, 80, &q, err, sizeof(err)) == 0);
    rc = tw_path_load_csv(path, 0, 80, 80, &p, err, sizeof(err));
    bool same = rc == 0 && p.count == q.count && p.count == 9000;
    for (uint32_t k = 0; same && k < p.count; k++)
        same = p.keys[k].pos.cell.i == q.keys[k].pos.cell.i &&
               p.keys[k].pos.cell.j == q.keys[k].pos.cell.j &&
               memcmp(p.keys[k].pos.local, q.keys[k].pos.local, sizeof(float) * 3) == 0 &&
               p.keys[k].yaw == q.keys[k].yaw && p.keys[k].pitch == q.keys[k].pitch;
    CHECK_MSG(same, "blocks: %s (%u rows, %u from memory)", err, p.count, q.count);
    tw_path_finish(&p);
    tw_path_finish(&q);
    /* Row 3001 made 2000 characters long. */
    size_t at = 0;
    for (int line = 0; line < 3001; line++)
        at = (size_t)(strchr(text + at, '\n') - text) + 1;
    char *longer = malloc(n + 2000);
    CHECK(longer != NULL);
    memcpy(longer, text, at);
    memset(longer + at, ' ', 2000);
    memcpy(longer + at + 2000, text + at, n - at);
    write_file(path, longer, n + 2000);
    rc = tw_path_load_csv(path, 0, 80, 80, &p, err, sizeof(err));
    CHECK_MSG(rc == TW_ERR_FORMAT && strstr(err, "long.csv:3002: line longer than 1022 "
                                               "characters"),
              "long line: %s", err);
    free(longer);
    free(text);
    unlink(path);
    rmdir(dir);
}

/* More rows than a path may have (TW_PATH_MAX_ROWS): refused at the first
 * row beyond (the slow suite: ten million rows are read first). */
static void test_row_limit(void)
{
    snprintf(dir, sizeof(dir), "/tmp/tw-test-paths-XXXXXX");
    CHECK(mkdtemp(dir) != NULL);
    char path[256];
    snprintf(path, sizeof(path), "%s", join("rows.csv"));
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (!f)
        return;
    fputs(HEADER, f);
    for (uint32_t k = 0; k <= TW_PATH_MAX_ROWS; k++)
        fputs("0,0,1,1,1,0,0\n", f);
    fputs("this row is never read\n", f);
    fclose(f);
    struct tw_path p;
    char err[512];
    const int rc = tw_path_load_csv(path, 0, 80, 80, &p, err, sizeof(err));
    CHECK_MSG(rc == TW_ERR_LIMIT && strstr(err, "rows.csv:10000002: more than 10000000 camera "
                                               "rows, the most frames a path may have"),
              "row limit: %s", err);
    unlink(path);
    rmdir(dir);
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "rows") == 0) {
        test_row_limit();
        return check_summary("test-paths rows");
    }
    test_messages();
    test_good_file();
    test_files();
    snprintf(dir, sizeof(dir), "/tmp/tw-test-paths-XXXXXX");
    test_streaming();
    return check_summary("test-paths");
}

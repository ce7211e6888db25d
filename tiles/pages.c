/* Page-granular blocks for packed structures (pages.h). */
#define _DEFAULT_SOURCE /* MAP_ANONYMOUS: not in POSIX 2008 */

#include "tiles/pages.h"

#include <stdint.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <unistd.h>

/* bytes rounded up to whole pages; 0 when that would not fit a size_t. */
static size_t mapping_length(size_t bytes)
{
    const long page_size = sysconf(_SC_PAGESIZE);
    const size_t page = page_size > 0 ? (size_t)page_size : 4096u;
    if (bytes > SIZE_MAX - (page - 1))
        return 0;
    return (bytes + page - 1) / page * page;
}

void *tw_pages_alloc(size_t bytes)
{
    if (bytes < TW_PAGES_MAP_MIN)
        return malloc(bytes ? bytes : 1);
    const size_t length = mapping_length(bytes);
    if (!length)
        return NULL;
    void *block = mmap(NULL, length, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    return block == MAP_FAILED ? NULL : block;
}

void tw_pages_free(void *block, size_t bytes)
{
    if (!block)
        return;
    if (bytes < TW_PAGES_MAP_MIN) {
        free(block);
        return;
    }
    /* The length tw_pages_alloc() mapped: it fitted then, so it fits now. */
    (void)munmap(block, mapping_length(bytes));
}

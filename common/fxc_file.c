/* Writing a whole file, every step checked (fxc_file.h). */
#include "fxc_file.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

bool fxc_write_whole_file(const char *path, const void *bytes, size_t len, char *msg, size_t cap)
{
    FILE *file = fopen(path, "wb");
    if (!file) {
        if (msg && cap)
            snprintf(msg, cap, "%s: cannot write: %s", path, strerror(errno));
        return false;
    }
    bool ok = fwrite(bytes, 1, len, file) == len && fflush(file) == 0;
    int saved = errno;
    if (fclose(file) != 0 && ok) {
        ok = false;
        saved = errno;
    }
    if (!ok) {
        fxc_remove_partial(path);
        if (msg && cap)
            snprintf(msg, cap, "%s: cannot write: %s", path, strerror(saved ? saved : EIO));
    }
    return ok;
}

void fxc_remove_partial(const char *path)
{
    struct stat st;
    if (lstat(path, &st) == 0 && (S_ISREG(st.st_mode) || S_ISLNK(st.st_mode)))
        remove(path);
}

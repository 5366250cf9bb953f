/* fxc_result.h: the one table of result codes every fxcache module shares (as libuv's UV_ERRNO_MAP).
 *
 * Header-only, so modules that depend on nothing else of ours (cache, scene) can use it without a link
 * dependency. Codes are negative, 0 is success. Modules may keep their own enum names (osc_result,
 * scene_result) but their values are these codes, so a code means the same thing wherever it appears and
 * fxc_strerror() names any of them. Programming errors are asserted, never returned. */
#ifndef FXC_RESULT_H
#define FXC_RESULT_H

#define FXC_RESULT_LIST(X)                                                                                   \
    X(FXC_OK, 0, "ok")                                                                                       \
    X(FXC_ERR_INVALID, -1, "invalid argument or description")                                                \
    X(FXC_ERR_NOMEM, -2, "out of memory")                                                                    \
    X(FXC_ERR_NO_POOL, -3, "the effect has no block pool")                                                   \
    X(FXC_ERR_POOL_EXHAUSTED, -4, "every block of the effect's pool is requested this frame")                \
    X(FXC_ERR_TABLE_FULL, -5, "the hash table is at its maximum load")                                       \
    X(FXC_ERR_NOT_FOUND, -6, "not found")                                                                    \
    X(FXC_ERR_IO, -7, "cannot read or write a file")                                                         \
    X(FXC_ERR_FORMAT, -8, "unsupported or malformed file")                                                   \
    X(FXC_ERR_JSON, -9, "malformed scene description")                                                       \
    X(FXC_ERR_CONTENT, -10, "invalid scene content")                                                         \
    X(FXC_ERR_RANGE, -11, "value out of range")                                                              \
    X(FXC_ERR_EMPTY, -12, "empty scene")                                                                     \
    X(FXC_ERR_EMBREE, -13, "Embree error")                                                                   \
    X(FXC_ERR_STALE_ID, -14, "no such viewer: the id is stale, was removed or never existed")                \
    X(FXC_ERR_NO_SLOT, -15, "every viewer slot is taken")                                                    \
    X(FXC_ERR_CAMERA, -16,                                                                                   \
      "invalid camera (non-finite, position equals target, fov outside (0, 180), or beyond 1e13 m)")         \
    X(FXC_ERR_EFFECTS, -17, "invalid effect list (unknown dependency, too many effects, or a bad table)")    \
    X(FXC_ERR_THREADS, -18, "cannot start threads")                                                          \
    X(FXC_ERR_BAD_MAGIC, -19, "not an fxcache message (bad magic)")                                          \
    X(FXC_ERR_VERSION, -20, "unsupported protocol version")                                                  \
    X(FXC_ERR_TRUNCATED, -21, "message truncated")                                                           \
    X(FXC_ERR_TRAILING, -22, "trailing bytes after the message")                                             \
    X(FXC_ERR_TOO_LARGE, -23, "message or payload too large")                                                \
    X(FXC_ERR_UNKNOWN_TYPE, -24, "unknown message type")                                                     \
    X(FXC_ERR_CODEC, -25, "payload does not decode")                                                         \
    X(FXC_ERR_PROTOCOL, -26, "message not allowed now (protocol order)")                                     \
    X(FXC_ERR_UNAUTHORIZED, -27, "missing or wrong access token")                                            \
    X(FXC_ERR_LIMIT, -28, "over a server limit (viewers, resolution, message size or camera rate)")          \
    X(FXC_ERR_SHUTDOWN, -29, "the server is shutting down")

typedef enum fxc_result {
#define FXC_RESULT_ENUM(name, value, text) name = value,
    FXC_RESULT_LIST(FXC_RESULT_ENUM)
#undef FXC_RESULT_ENUM
} fxc_result;

/* The text of a result code: a static string, "unknown result" for values outside the table. */
static inline const char *fxc_strerror(int code)
{
    switch (code) {
#define FXC_RESULT_CASE(name, value, text)                                                                   \
    case value: return text;
        FXC_RESULT_LIST(FXC_RESULT_CASE)
#undef FXC_RESULT_CASE
    }
    return "unknown result";
}

/* Every code in the table, for tests and tools: the number of codes, and code i. */
static inline int fxc_result_count(void)
{
    static const int codes[] = {
#define FXC_RESULT_CODE(name, value, text) value,
        FXC_RESULT_LIST(FXC_RESULT_CODE)
#undef FXC_RESULT_CODE
    };
    return (int)(sizeof codes / sizeof codes[0]);
}

static inline int fxc_result_code(int i)
{
    static const int codes[] = {
#define FXC_RESULT_CODE(name, value, text) value,
        FXC_RESULT_LIST(FXC_RESULT_CODE)
#undef FXC_RESULT_CODE
    };
    return i >= 0 && i < (int)(sizeof codes / sizeof codes[0]) ? codes[i] : 1;
}

#endif

/* JSON scene descriptions: reads a *.json file (through jansson) into a scene.
 *
 * A scene description lists mesh files (imported through Assimp by scene__import_file) with a transform and
 * an optional material each, the lights, the sky, the texel density, the ambient-occlusion radius, effect
 * overrides and a default camera. It says exactly what the scene has: a description without "lights" and
 * "sky" keys gets no lights and no sky (plain mesh files get a default sun and sky elsewhere, not here).
 * The format is documented for users in docs/SCENE_FORMAT.md; the summary:
 *
 *   {
 *     "version": 1,                                   required; newer versions are refused
 *     "meshes": [                                     required, at least one entry
 *       { "file": "models/bunny.obj",                 required; relative to the folder of the JSON file
 *         "name": "bunny",                            optional; names the mesh (or prefixes the file's meshes)
 *         "transform": { "translate": [x, y, z],      optional; applied as T * Rz * Ry * Rx * S
 *                        "rotate_deg": [x, y, z],     degrees about the world X, then Y, then Z axis
 *                        "scale": s or [x, y, z] },   non-zero
 *           or "transform": { "matrix": [16 numbers] } or "transform": [16 numbers]
 *                                                     row-major affine 4x4, last row 0 0 0 1, not singular
 *         "material": { "diffuse": [r, g, b],         optional; replaces every material of the file;
 *                       "texture": "wood.png",        linear albedo in 0..1 (default 0.8 grey, or white
 *                       "emission": [r, g, b],        when a texture is given); texture relative to the JSON;
 *                       "name": "wood" } },           emission: radiance of the front faces, >= 0 (default 0)
 *       { "builtin": "default",                       the embedded default scene's geometry and materials
 *         "transform": { ... } }                      (not its lights, sky or camera); optional transform
 *     ],
 *     "lights": [                                     optional; absent or [] means no lights
 *       { "type": "directional", "direction": [x, y, z],   direction the light travels (into the scene)
 *         "color": [r, g, b], "intensity": x },            color default [1,1,1], intensity default 1, >= 0
 *       { "type": "point", "position": [x, y, z], "color": [r, g, b], "intensity": x } ],
 *     "sky": { "color": [r, g, b], "intensity": x },  optional; absent means no sky (no ambient light)
 *     "texel_density": 100 or "auto",                 level-0 texels per metre, 1e-6 .. 1e6 (default "auto")
 *     "ao_radius": 0.5,                               metres, > 0 (default: a tenth of the scene diagonal)
 *     "effects": { "shadows": "auto", "ao": "on", "indirect": "off" },  each "auto" (default), "on" or "off"
 *     "camera": { "position": [x, y, z], "target": [x, y, z], "fov_deg": 60 }  optional default camera
 *   }
 *
 * Every object may also hold a "comment" string, which is ignored. Any other unknown field is an error.
 *
 * Errors are one line each: "scene.json:12:5: <what>" for malformed JSON (line and column from jansson),
 * else "scene.json: lights[1].intensity: must be a finite number >= 0", naming the file and the JSON path.
 * Structure errors (unknown fields, wrong types, missing fields) are SCENE_ERR_JSON; bad values are
 * SCENE_ERR_INVALID; a texel density outside the allowed range is SCENE_ERR_RANGE (a density so large that
 * an island overflows the 12-bit block coordinates is caught later, at island building, also RANGE); an
 * empty "meshes" list is SCENE_ERR_EMPTY; a newer version is SCENE_ERR_FORMAT; an unreadable JSON file is
 * SCENE_ERR_IO. Errors from mesh import keep their own code and gain the JSON path as a prefix.
 *
 * Everything cheap is checked first (the whole description, every mesh entry), and only then are the mesh
 * files imported, so a typo in the last light does not cost the import of a large mesh. */
#include "scene_internal.h"

#include <float.h>
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum {
    JSON_SCENE_VERSION = 1, /* the newest version this reader understands */
    JSON_PATH_CAP = 1024,   /* resolved file paths */
    JSON_WHERE_CAP = 128,   /* JSON paths such as "meshes[12].transform.scale" */
};

/* Floats, as the value is compared after its conversion to float: the double 1e-6 is larger than the float
 * nearest to it, so a bound in double refused the documented end "texel_density": 1e-6 itself. */
#define JSON_DENSITY_MIN   1e-6f /* texels per metre: one texel per 1000 km */
#define JSON_DENSITY_MAX   1e6f  /* texels per metre: a texel of 1 um (the same bound as --density) */
#define JSON_AO_RADIUS_MAX 1e9   /* metres */
#define JSON_DEFAULT_FOV   60.0f /* degrees */

/* What the reader carries through every check: the file for messages, its folder for relative paths. */
typedef struct json_ctx {
    const char *path;        /* the JSON file as given, for messages */
    char dir[JSON_PATH_CAP]; /* its folder with a trailing '/', or "" for the current folder */
    scene_error *err;
} json_ctx;

/* One checked "meshes" entry, imported in a second pass. */
typedef struct json_mesh_entry {
    bool builtin;             /* {"builtin": "default"} */
    char file[JSON_PATH_CAP]; /* resolved against the JSON file's folder */
    bool has_name;
    char name[128];
    bool has_xform;
    double xform[16]; /* row-major affine, applied in double */
    bool has_material;
    scene_material material; /* texture index filled at import time */
    bool has_texture;
    char texture[JSON_PATH_CAP];
} json_mesh_entry;

/* Fills err with "file: where: message" (or "file: message" when where is empty) and returns code; control
 * characters in the message become '?'. */
__attribute__((format(printf, 4, 5))) static scene_result json_fail(const json_ctx *ctx, scene_result code,
                                                                    const char *where, const char *fmt, ...)
{
    char text[400];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    for (char *c = text; *c;
         c++) /* keys and strings from the file may hold "\n": keep the message one line */
        if ((unsigned char)*c < 0x20 || *c == 0x7f)
            *c = '?';
    if (where && where[0])
        return scene__fail(ctx->err, code, "%s: %s: %s", ctx->path, where, text);
    return scene__fail(ctx->err, code, "%s: %s", ctx->path, text);
}

/* Writes the JSON path of field key inside the object at where ("lights[1]" + "color" -> "lights[1].color"). */
static void json_field_path(char *out, size_t cap, const char *where, const char *key)
{
    int written = snprintf(out, cap, "%s%s%s", where, where[0] ? "." : "", key);
    if (written < 0 || (size_t)written >= cap)
        snprintf(out, cap, "%s", key); /* too deep to print whole: the key alone still says what */
}

/* Writes the JSON path of element index of the array at where ("meshes" + 2 -> "meshes[2]"). */
static void json_element_path(char *out, size_t cap, const char *where, size_t index)
{
    int written = snprintf(out, cap, "%s[%zu]", where, index);
    if (written < 0 || (size_t)written >= cap)
        snprintf(out, cap, "[%zu]", index);
}

/* The JSON type of a value as a word for messages. */
static const char *json_type_word(const json_t *value)
{
    switch (json_typeof(value)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER: return "an integer";
    case JSON_REAL: return "a real number";
    case JSON_TRUE:
    case JSON_FALSE: return "a boolean";
    case JSON_NULL: return "null";
    }
    return "something else";
}

/* Checks that value (at where) is an object whose keys are all in allowed (plus "comment", a string). */
static scene_result json_check_object(const json_ctx *ctx, const json_t *value, const char *where,
                                      const char *const *allowed, size_t allowed_count)
{
    if (!json_is_object(value))
        return json_fail(ctx, SCENE_ERR_JSON, where, "must be an object, not %s", json_type_word(value));
    const char *key;
    json_t *member;
    json_object_foreach((json_t *)value, key, member)
    {
        if (strcmp(key, "comment") == 0) {
            if (!json_is_string(member)) {
                char field[JSON_WHERE_CAP];
                json_field_path(field, sizeof field, where, key);
                return json_fail(ctx, SCENE_ERR_JSON, field, "must be a string, not %s",
                                 json_type_word(member));
            }
            continue;
        }
        bool known = false;
        for (size_t i = 0; i < allowed_count && !known; i++)
            known = strcmp(key, allowed[i]) == 0;
        if (!known) {
            char list[256] = "";
            size_t used = 0;
            for (size_t i = 0; i < allowed_count; i++) {
                int n = snprintf(list + used, sizeof list - used, "%s%s", i ? ", " : "", allowed[i]);
                if (n < 0 || (size_t)n >= sizeof list - used)
                    break;
                used += (size_t)n;
            }
            return json_fail(ctx, SCENE_ERR_JSON, where[0] ? where : "(top level)",
                             "unknown field '%s' (allowed: %s, comment)", key, list);
        }
    }
    return SCENE_OK;
}

/* Reads a finite number (finite also as a float) from value at where into out. */
static scene_result json_read_number(const json_ctx *ctx, const json_t *value, const char *where, float *out)
{
    if (!json_is_number(value))
        return json_fail(ctx, SCENE_ERR_JSON, where, "must be a number, not %s", json_type_word(value));
    double number = json_number_value(value);
    float single = (float)number;
    if (!isfinite(number) || !isfinite(single))
        return json_fail(ctx, SCENE_ERR_INVALID, where, "must be a finite number (%g does not fit a float)",
                         number);
    *out = single;
    return SCENE_OK;
}

/* Reads an optional number field key of obj; leaves *out alone when the field is absent. */
static scene_result json_get_number(const json_ctx *ctx, const json_t *obj, const char *where,
                                    const char *key, float *out, bool *present)
{
    const json_t *value = json_object_get(obj, key);
    if (present)
        *present = value != NULL;
    if (!value)
        return SCENE_OK;
    char field[JSON_WHERE_CAP];
    json_field_path(field, sizeof field, where, key);
    return json_read_number(ctx, value, field, out);
}

/* Reads a finite number from value at where into out, in double: positions and transforms keep the
 * precision the file gives them (a scene far from the origin needs more than a float has). */
static scene_result json_read_number_d(const json_ctx *ctx, const json_t *value, const char *where,
                                       double *out)
{
    if (!json_is_number(value))
        return json_fail(ctx, SCENE_ERR_JSON, where, "must be a number, not %s", json_type_word(value));
    double number = json_number_value(value);
    if (!(fabs(number) <= FLT_MAX))
        return json_fail(ctx, SCENE_ERR_INVALID, where, "must be a finite number (%g does not fit a float)",
                         number);
    *out = number;
    return SCENE_OK;
}

/* Reads an array of count finite numbers from value (at where) into out, in double. */
static scene_result json_read_numbers_d(const json_ctx *ctx, const json_t *value, const char *where,
                                        double *out, size_t count)
{
    if (!json_is_array(value) || json_array_size(value) != count)
        return json_fail(ctx, SCENE_ERR_JSON, where, "must be an array of %zu numbers, not %s%s", count,
                         json_type_word(value), json_is_array(value) ? " of another length" : "");
    for (size_t i = 0; i < count; i++) {
        char element[JSON_WHERE_CAP];
        json_element_path(element, sizeof element, where, i);
        scene_result r = json_read_number_d(ctx, json_array_get(value, i), element, &out[i]);
        if (r != SCENE_OK)
            return r;
    }
    return SCENE_OK;
}

/* Reads an optional array of count finite numbers, field key of obj, in double; out alone when absent. */
static scene_result json_get_numbers_d(const json_ctx *ctx, const json_t *obj, const char *where,
                                       const char *key, double *out, size_t count, bool *present)
{
    const json_t *value = json_object_get(obj, key);
    if (present)
        *present = value != NULL;
    if (!value)
        return SCENE_OK;
    char field[JSON_WHERE_CAP];
    json_field_path(field, sizeof field, where, key);
    return json_read_numbers_d(ctx, value, field, out, count);
}

/* Reads an array of count (at most 16) finite numbers from value (at where) into out, as floats: the double
 * reader below, then one rounding. */
static scene_result json_read_numbers(const json_ctx *ctx, const json_t *value, const char *where, float *out,
                                      size_t count)
{
    double values[16];
    if (count > 16)
        return json_fail(ctx, SCENE_ERR_JSON, where, "too many numbers (%zu)", count);
    scene_result r = json_read_numbers_d(ctx, value, where, values, count);
    for (size_t i = 0; r == SCENE_OK && i < count; i++)
        out[i] = (float)values[i];
    return r;
}

/* Reads an optional array of count finite numbers, field key of obj; leaves out alone when absent. */
static scene_result json_get_numbers(const json_ctx *ctx, const json_t *obj, const char *where,
                                     const char *key, float *out, size_t count, bool *present)
{
    const json_t *value = json_object_get(obj, key);
    if (present)
        *present = value != NULL;
    if (!value)
        return SCENE_OK;
    char field[JSON_WHERE_CAP];
    json_field_path(field, sizeof field, where, key);
    return json_read_numbers(ctx, value, field, out, count);
}

/* Reads an optional non-empty string field key of obj into out (cap bytes); NULL-safe on absence. */
static scene_result json_get_string(const json_ctx *ctx, const json_t *obj, const char *where,
                                    const char *key, char *out, size_t cap, bool *present)
{
    const json_t *value = json_object_get(obj, key);
    if (present)
        *present = value != NULL;
    if (!value)
        return SCENE_OK;
    char field[JSON_WHERE_CAP];
    json_field_path(field, sizeof field, where, key);
    if (!json_is_string(value))
        return json_fail(ctx, SCENE_ERR_JSON, field, "must be a string, not %s", json_type_word(value));
    const char *text = json_string_value(value);
    size_t length = json_string_length(value);
    if (length == 0)
        return json_fail(ctx, SCENE_ERR_INVALID, field, "must not be empty");
    if (strlen(text) != length)
        return json_fail(ctx, SCENE_ERR_INVALID, field, "must not contain a NUL character");
    if (length >= cap)
        return json_fail(ctx, SCENE_ERR_INVALID, field, "is too long (%zu bytes, at most %zu)", length,
                         cap - 1);
    memcpy(out, text, length + 1);
    return SCENE_OK;
}

/* Checks a colour (at where.key) has no negative component. */
static scene_result json_check_color(const json_ctx *ctx, const char *where, const char *key,
                                     const float rgb[3])
{
    for (int i = 0; i < 3; i++) {
        if (rgb[i] < 0.0f) {
            char field[JSON_WHERE_CAP];
            json_field_path(field, sizeof field, where, key);
            return json_fail(ctx, SCENE_ERR_INVALID, field, "components must be >= 0 (component %d is %g)", i,
                             (double)rgb[i]);
        }
    }
    return SCENE_OK;
}

/* Resolves a path from the description against the folder of the JSON file (absolute paths stay). */
static scene_result json_resolve_path(const json_ctx *ctx, const char *where, const char *relative, char *out,
                                      size_t cap)
{
    int written = relative[0] == '/' ? snprintf(out, cap, "%s", relative)
                                     : snprintf(out, cap, "%s%s", ctx->dir, relative);
    if (written < 0 || (size_t)written >= cap)
        return json_fail(ctx, SCENE_ERR_INVALID, where, "path '%s' is too long once resolved", relative);
    return SCENE_OK;
}

/* Multiplies 3x3 row-major matrices: out = a * b. */
static void json_mat3_mul(const double a[9], const double b[9], double out[9])
{
    for (int row = 0; row < 3; row++)
        for (int col = 0; col < 3; col++)
            out[row * 3 + col] = a[row * 3 + 0] * b[0 * 3 + col] + a[row * 3 + 1] * b[1 * 3 + col] +
                                 a[row * 3 + 2] * b[2 * 3 + col];
}

/* Reads "transform" of a mesh entry (where names it) into a row-major affine 4x4 matrix. */
static scene_result json_read_transform(const json_ctx *ctx, const json_t *value, const char *where,
                                        double xform[16])
{
    char field[JSON_WHERE_CAP];
    scene_result r;
    double matrix[16];
    bool has_matrix = false;

    if (json_is_array(value)) {
        /* The bare 16-number form. */
        if ((r = json_read_numbers_d(ctx, value, where, matrix, 16)) != SCENE_OK)
            return r;
        has_matrix = true;
        snprintf(field, sizeof field, "%s", where);
    } else {
        static const char *const allowed[] = {"translate", "rotate_deg", "scale", "matrix"};
        r = json_check_object(ctx, value, where, allowed, 4);
        if (r != SCENE_OK)
            return r;
        r = json_get_numbers_d(ctx, value, where, "matrix", matrix, 16, &has_matrix);
        if (r != SCENE_OK)
            return r;
        json_field_path(field, sizeof field, where, "matrix");
    }

    if (has_matrix) {
        if (json_is_object(value) &&
            (json_object_get(value, "translate") || json_object_get(value, "rotate_deg") ||
             json_object_get(value, "scale")))
            return json_fail(ctx, SCENE_ERR_JSON, where,
                             "'matrix' cannot be combined with translate, rotate_deg or scale");
        if (matrix[12] != 0.0 || matrix[13] != 0.0 || matrix[14] != 0.0 || matrix[15] != 1.0)
            return json_fail(ctx, SCENE_ERR_INVALID, field,
                             "must be affine: the last row must be 0 0 0 1 (it is %g %g %g %g)", matrix[12],
                             matrix[13], matrix[14], matrix[15]);
        double det = matrix[0] * (matrix[5] * matrix[10] - matrix[6] * matrix[9]) -
                     matrix[1] * (matrix[4] * matrix[10] - matrix[6] * matrix[8]) +
                     matrix[2] * (matrix[4] * matrix[9] - matrix[5] * matrix[8]);
        if (!(fabs(det) > 0.0) || !isfinite(det))
            return json_fail(ctx, SCENE_ERR_INVALID, field, "is singular (it flattens the mesh)");
        memcpy(xform, matrix, sizeof matrix);
        return SCENE_OK;
    }

    double translate[3] = {0, 0, 0}, rotate_deg[3] = {0, 0, 0}, scale[3] = {1, 1, 1};
    if ((r = json_get_numbers_d(ctx, value, where, "translate", translate, 3, NULL)) != SCENE_OK ||
        (r = json_get_numbers_d(ctx, value, where, "rotate_deg", rotate_deg, 3, NULL)) != SCENE_OK)
        return r;
    const json_t *scale_value = json_object_get(value, "scale");
    json_field_path(field, sizeof field, where, "scale");
    if (scale_value && json_is_number(scale_value)) {
        if ((r = json_read_number_d(ctx, scale_value, field, &scale[0])) != SCENE_OK)
            return r;
        scale[1] = scale[2] = scale[0];
    } else if (scale_value && !json_is_array(scale_value)) {
        return json_fail(ctx, SCENE_ERR_JSON, field, "must be a number or an array of 3 numbers, not %s",
                         json_type_word(scale_value));
    } else if ((r = json_get_numbers_d(ctx, value, where, "scale", scale, 3, NULL)) != SCENE_OK) {
        return r;
    }
    for (int i = 0; i < 3; i++)
        if (scale[i] == 0.0)
            return json_fail(ctx, SCENE_ERR_INVALID, field, "must not be zero (it flattens the mesh)");

    /* M = T * Rz * Ry * Rx * S: scale, then rotate about X, Y, Z (world axes), then translate. */
    double radians[3], c[3], s[3];
    for (int i = 0; i < 3; i++) {
        radians[i] = rotate_deg[i] * (3.14159265358979323846 / 180.0);
        c[i] = cos(radians[i]);
        s[i] = sin(radians[i]);
    }
    const double rx[9] = {1, 0, 0, 0, c[0], -s[0], 0, s[0], c[0]};
    const double ry[9] = {c[1], 0, s[1], 0, 1, 0, -s[1], 0, c[1]};
    const double rz[9] = {c[2], -s[2], 0, s[2], c[2], 0, 0, 0, 1};
    double ryx[9], rzyx[9];
    json_mat3_mul(ry, rx, ryx);
    json_mat3_mul(rz, ryx, rzyx);
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++)
            xform[row * 4 + col] = rzyx[row * 3 + col] * scale[col];
        xform[row * 4 + 3] = translate[row];
    }
    xform[12] = xform[13] = xform[14] = 0.0;
    xform[15] = 1.0;
    return SCENE_OK;
}

/* Checks one "meshes" entry (at where) and records it for the import pass. */
static scene_result json_read_mesh_entry(const json_ctx *ctx, const json_t *value, const char *where,
                                         json_mesh_entry *entry)
{
    scene_result r;
    char field[JSON_WHERE_CAP];
    memset(entry, 0, sizeof *entry);
    if (json_is_object(value) && json_object_get(value, "builtin")) {
        static const char *const allowed_builtin[] = {"builtin", "transform"};
        if ((r = json_check_object(ctx, value, where, allowed_builtin, 2)) != SCENE_OK)
            return r;
        char which[32];
        if ((r = json_get_string(ctx, value, where, "builtin", which, sizeof which, NULL)) != SCENE_OK)
            return r;
        if (strcmp(which, "default") != 0) {
            json_field_path(field, sizeof field, where, "builtin");
            return json_fail(ctx, SCENE_ERR_INVALID, field,
                             "unknown builtin '%s' (the only one is \"default\")", which);
        }
        entry->builtin = true;
        const json_t *transform = json_object_get(value, "transform");
        if (transform) {
            json_field_path(field, sizeof field, where, "transform");
            if ((r = json_read_transform(ctx, transform, field, entry->xform)) != SCENE_OK)
                return r;
            entry->has_xform = true;
        }
        return SCENE_OK;
    }

    static const char *const allowed[] = {"file", "name", "transform", "material", "builtin"};
    if ((r = json_check_object(ctx, value, where, allowed, 5)) != SCENE_OK)
        return r;
    char relative[JSON_PATH_CAP];
    bool has_file = false;
    if ((r = json_get_string(ctx, value, where, "file", relative, sizeof relative, &has_file)) != SCENE_OK)
        return r;
    if (!has_file)
        return json_fail(ctx, SCENE_ERR_JSON, where,
                         "missing required field 'file' (or \"builtin\": \"default\")");
    json_field_path(field, sizeof field, where, "file");
    if ((r = json_resolve_path(ctx, field, relative, entry->file, sizeof entry->file)) != SCENE_OK)
        return r;
    if ((r = json_get_string(ctx, value, where, "name", entry->name, sizeof entry->name, &entry->has_name)) !=
        SCENE_OK)
        return r;

    const json_t *transform = json_object_get(value, "transform");
    if (transform) {
        json_field_path(field, sizeof field, where, "transform");
        if ((r = json_read_transform(ctx, transform, field, entry->xform)) != SCENE_OK)
            return r;
        entry->has_xform = true;
    }

    const json_t *material = json_object_get(value, "material");
    if (material) {
        static const char *const allowed_material[] = {"diffuse", "texture", "name", "emission"};
        char material_where[JSON_WHERE_CAP];
        json_field_path(material_where, sizeof material_where, where, "material");
        if ((r = json_check_object(ctx, material, material_where, allowed_material, 4)) != SCENE_OK)
            return r;
        scene_material *m = &entry->material;
        m->texture = -1;
        char texture_relative[JSON_PATH_CAP];
        if ((r = json_get_string(ctx, material, material_where, "texture", texture_relative,
                                 sizeof texture_relative, &entry->has_texture)) != SCENE_OK)
            return r;
        float grey = entry->has_texture ? 1.0f : 0.8f; /* a texture alone shows its own colours */
        m->diffuse[0] = m->diffuse[1] = m->diffuse[2] = grey;
        if ((r = json_get_numbers(ctx, material, material_where, "diffuse", m->diffuse, 3, NULL)) != SCENE_OK)
            return r;
        for (int i = 0; i < 3; i++) {
            if (m->diffuse[i] < 0.0f || m->diffuse[i] > 1.0f) {
                json_field_path(field, sizeof field, material_where, "diffuse");
                return json_fail(ctx, SCENE_ERR_INVALID, field,
                                 "components must be albedos in 0..1 (component %d is %g)", i,
                                 (double)m->diffuse[i]);
            }
        }
        /* Emission: radiance (not an albedo), any size a float holds, >= 0; default none. */
        if ((r = json_get_numbers(ctx, material, material_where, "emission", m->emission, 3, NULL)) !=
            SCENE_OK)
            return r;
        for (int i = 0; i < 3; i++) {
            if (!(m->emission[i] >= 0.0f) || !isfinite(m->emission[i])) {
                json_field_path(field, sizeof field, material_where, "emission");
                return json_fail(ctx, SCENE_ERR_INVALID, field,
                                 "components must be radiances >= 0 that fit a float (component %d is %g)", i,
                                 (double)m->emission[i]);
            }
        }
        if (entry->has_texture) {
            json_field_path(field, sizeof field, material_where, "texture");
            if ((r = json_resolve_path(ctx, field, texture_relative, entry->texture,
                                       sizeof entry->texture)) != SCENE_OK)
                return r;
        }
        bool has_material_name = false;
        if ((r = json_get_string(ctx, material, material_where, "name", m->name, sizeof m->name,
                                 &has_material_name)) != SCENE_OK)
            return r;
        if (!has_material_name)
            snprintf(m->name, sizeof m->name, "%s", entry->has_name ? entry->name : "json override");
        entry->has_material = true;
    }
    return SCENE_OK;
}

/* Reads the "lights" array and appends each light to s. */
static scene_result json_read_lights(const json_ctx *ctx, scene *s, const json_t *lights)
{
    if (!json_is_array(lights))
        return json_fail(ctx, SCENE_ERR_JSON, "lights", "must be an array, not %s", json_type_word(lights));
    for (size_t index = 0; index < json_array_size(lights); index++) {
        const json_t *value = json_array_get(lights, index);
        char where[JSON_WHERE_CAP], field[JSON_WHERE_CAP];
        json_element_path(where, sizeof where, "lights", index);
        static const char *const allowed[] = {"type", "direction", "position", "color", "intensity"};
        scene_result r = json_check_object(ctx, value, where, allowed, 5);
        if (r != SCENE_OK)
            return r;

        char type[32];
        bool has_type = false;
        if ((r = json_get_string(ctx, value, where, "type", type, sizeof type, &has_type)) != SCENE_OK)
            return r;
        if (!has_type)
            return json_fail(ctx, SCENE_ERR_JSON, where,
                             "missing required field 'type' (\"directional\" or \"point\")");
        scene_light light;
        memset(&light, 0, sizeof light);
        light.color[0] = light.color[1] = light.color[2] = 1.0f;
        light.intensity = 1.0f;
        bool has_direction = false, has_position = false;
        double position[3] = {0, 0, 0}; /* world, in double: the scene's origin is subtracted before float */
        if ((r = json_get_numbers(ctx, value, where, "direction", light.direction, 3, &has_direction)) !=
                SCENE_OK ||
            (r = json_get_numbers_d(ctx, value, where, "position", position, 3, &has_position)) != SCENE_OK ||
            (r = json_get_numbers(ctx, value, where, "color", light.color, 3, NULL)) != SCENE_OK ||
            (r = json_get_number(ctx, value, where, "intensity", &light.intensity, NULL)) != SCENE_OK)
            return r;
        if ((r = json_check_color(ctx, where, "color", light.color)) != SCENE_OK)
            return r;
        json_field_path(field, sizeof field, where, "intensity");
        if (light.intensity < 0.0f)
            return json_fail(ctx, SCENE_ERR_INVALID, field, "must be a finite number >= 0 (it is %g)",
                             (double)light.intensity);

        if (strcmp(type, "directional") == 0) {
            light.type = SCENE_LIGHT_DIRECTIONAL;
            if (!has_direction)
                return json_fail(ctx, SCENE_ERR_JSON, where,
                                 "missing required field 'direction' (a directional "
                                 "light needs the direction it travels)");
            if (has_position)
                return json_fail(ctx, SCENE_ERR_JSON, where,
                                 "field 'position' does not apply to a directional light (use 'direction')");
            double length = sqrt((double)light.direction[0] * light.direction[0] +
                                 (double)light.direction[1] * light.direction[1] +
                                 (double)light.direction[2] * light.direction[2]);
            json_field_path(field, sizeof field, where, "direction");
            if (!(length > 1e-20) || !isfinite(length))
                return json_fail(ctx, SCENE_ERR_INVALID, field, "must not be the zero vector");
            for (int i = 0; i < 3; i++)
                light.direction[i] = (float)(light.direction[i] / length);
        } else if (strcmp(type, "point") == 0) {
            light.type = SCENE_LIGHT_POINT;
            if (!has_position)
                return json_fail(ctx, SCENE_ERR_JSON, where,
                                 "missing required field 'position' (a point light "
                                 "needs a position)");
            if (has_direction)
                return json_fail(ctx, SCENE_ERR_JSON, where,
                                 "field 'direction' does not apply to a point light (use 'position')");
        } else {
            json_field_path(field, sizeof field, where, "type");
            return json_fail(ctx, SCENE_ERR_INVALID, field,
                             "unknown light type '%s' (\"directional\" or \"point\")", type);
        }
        char light_where[JSON_WHERE_CAP + 300];
        snprintf(light_where, sizeof light_where, "%s: %s", ctx->path, where);
        if ((r = scene__add_light_world(s, &light, position, light_where, ctx->err)) != SCENE_OK)
            return r;
    }
    return SCENE_OK;
}

/* Reads "sky" into s->sky_color and s->sky_intensity. */
static scene_result json_read_sky(const json_ctx *ctx, scene *s, const json_t *sky)
{
    static const char *const allowed[] = {"color", "intensity"};
    scene_result r = json_check_object(ctx, sky, "sky", allowed, 2);
    if (r != SCENE_OK)
        return r;
    float color[3] = {1, 1, 1}, intensity = 1.0f;
    if ((r = json_get_numbers(ctx, sky, "sky", "color", color, 3, NULL)) != SCENE_OK ||
        (r = json_get_number(ctx, sky, "sky", "intensity", &intensity, NULL)) != SCENE_OK ||
        (r = json_check_color(ctx, "sky", "color", color)) != SCENE_OK)
        return r;
    if (intensity < 0.0f)
        return json_fail(ctx, SCENE_ERR_INVALID, "sky.intensity", "must be a finite number >= 0 (it is %g)",
                         (double)intensity);
    double brightest = fmax(fmax(color[0], color[1]), color[2]) * (double)intensity;
    if (brightest > FLT_MAX) /* as a light's (scene__add_light_world): 0 x inf would be NaN */
        return json_fail(ctx, SCENE_ERR_INVALID, "sky",
                         "color x intensity must fit a float (it is %g, at most %g)", brightest,
                         (double)FLT_MAX);
    memcpy(s->sky_color, color, sizeof color);
    s->sky_intensity = intensity;
    return SCENE_OK;
}

/* Reads one effect override ("auto", "on", "off") named key of the "effects" object. */
static scene_result json_read_toggle(const json_ctx *ctx, const json_t *effects, const char *key,
                                     scene_toggle *out)
{
    char word[16], field[JSON_WHERE_CAP];
    bool present = false;
    json_field_path(field, sizeof field, "effects", key);
    const json_t *value = json_object_get(effects, key);
    if (value && !json_is_string(value))
        return json_fail(ctx, SCENE_ERR_JSON, field, "must be \"auto\", \"on\" or \"off\", not %s",
                         json_type_word(value));
    if (value && json_string_length(value) >= sizeof word)
        return json_fail(ctx, SCENE_ERR_INVALID, field, "must be \"auto\", \"on\" or \"off\"");
    scene_result r = json_get_string(ctx, effects, "effects", key, word, sizeof word, &present);
    if (r != SCENE_OK || !present)
        return r;
    if (strcmp(word, "auto") == 0)
        *out = SCENE_AUTO;
    else if (strcmp(word, "on") == 0)
        *out = SCENE_ON;
    else if (strcmp(word, "off") == 0)
        *out = SCENE_OFF;
    else
        return json_fail(ctx, SCENE_ERR_INVALID, field, "must be \"auto\", \"on\" or \"off\", not \"%s\"",
                         word);
    return SCENE_OK;
}

/* Reads "camera" into the scene's default camera. */
static scene_result json_read_camera(const json_ctx *ctx, scene *s, const json_t *camera)
{
    static const char *const allowed[] = {"position", "target", "fov_deg"};
    scene_result r = json_check_object(ctx, camera, "camera", allowed, 3);
    if (r != SCENE_OK)
        return r;
    double position[3], target[3]; /* world, in double: the scene's origin is subtracted before float */
    float fov_deg = JSON_DEFAULT_FOV;
    bool has_position = false, has_target = false;
    if ((r = json_get_numbers_d(ctx, camera, "camera", "position", position, 3, &has_position)) != SCENE_OK ||
        (r = json_get_numbers_d(ctx, camera, "camera", "target", target, 3, &has_target)) != SCENE_OK ||
        (r = json_get_number(ctx, camera, "camera", "fov_deg", &fov_deg, NULL)) != SCENE_OK)
        return r;
    if (!has_position)
        return json_fail(ctx, SCENE_ERR_JSON, "camera", "missing required field 'position'");
    if (!has_target)
        return json_fail(ctx, SCENE_ERR_JSON, "camera", "missing required field 'target'");
    if (position[0] == target[0] && position[1] == target[1] && position[2] == target[2])
        return json_fail(ctx, SCENE_ERR_INVALID, "camera.target", "must differ from camera.position");
    if (!(fov_deg > 0.0f && fov_deg < 180.0f))
        return json_fail(ctx, SCENE_ERR_INVALID, "camera.fov_deg", "must be in (0, 180) degrees (it is %g)",
                         (double)fov_deg);
    if (!scene__set_camera_world(s, position, target, fov_deg))
        return json_fail(ctx, SCENE_ERR_NOMEM, "camera", "out of memory");
    return SCENE_OK;
}

/* Reads "texel_density" (a number or "auto") and "ao_radius". */
static scene_result json_read_density_and_radius(const json_ctx *ctx, scene *s, const json_t *root)
{
    const json_t *density = json_object_get(root, "texel_density");
    if (density) {
        if (json_is_string(density)) {
            if (strcmp(json_string_value(density), "auto") != 0)
                return json_fail(ctx, SCENE_ERR_INVALID, "texel_density",
                                 "must be a number of texels per metre or \"auto\", not \"%s\"",
                                 json_string_value(density));
            s->density_auto = true;
        } else if (json_is_number(density)) {
            float value;
            scene_result r = json_read_number(ctx, density, "texel_density", &value);
            if (r != SCENE_OK)
                return r;
            if (!(value >= JSON_DENSITY_MIN && value <= JSON_DENSITY_MAX))
                return json_fail(ctx, SCENE_ERR_RANGE, "texel_density",
                                 "%g texels per metre is out of range (allowed %g .. %g, or \"auto\")",
                                 (double)value, (double)JSON_DENSITY_MIN, (double)JSON_DENSITY_MAX);
            s->texel_density = value;
            s->density_auto = false;
        } else {
            return json_fail(ctx, SCENE_ERR_JSON, "texel_density",
                             "must be a number of texels per metre or \"auto\", not %s",
                             json_type_word(density));
        }
    }
    const json_t *radius = json_object_get(root, "ao_radius");
    if (radius) {
        float value;
        scene_result r = json_read_number(ctx, radius, "ao_radius", &value);
        if (r != SCENE_OK)
            return r;
        if (!(value > 0.0f && value <= JSON_AO_RADIUS_MAX))
            return json_fail(ctx, SCENE_ERR_INVALID, "ao_radius", "must be > 0 and <= %g metres (it is %g)",
                             JSON_AO_RADIUS_MAX, (double)value);
        s->ao_radius = value;
    }
    return SCENE_OK;
}

/* Adds the embedded default scene's geometry and materials (moved by xform, may be NULL), without its lights,
 * sky and camera: a JSON scene says exactly which lights it has. */
static scene_result json_add_builtin_default(const json_ctx *ctx, scene *s, const double *xform,
                                             const char *where)
{
    uint32_t light_count = s->light_count;
    float sky_color[3];
    memcpy(sky_color, s->sky_color, sizeof sky_color);
    float sky_intensity = s->sky_intensity;
    bool has_camera = s->has_camera;
    float camera_pos[3], camera_target[3], camera_fov_deg = s->camera_fov_deg;
    memcpy(camera_pos, s->camera_pos, sizeof camera_pos);
    memcpy(camera_target, s->camera_target, sizeof camera_target);
    float ao_radius = s->ao_radius;

    scene_result r = scene__build_default_xform(s, xform, ctx->err);
    if (r != SCENE_OK) {
        char inner[sizeof ctx->err->msg];
        snprintf(inner, sizeof inner, "%s", ctx->err->msg);
        return json_fail(ctx, r, where, "%s", inner);
    }
    s->light_count = light_count; /* the array stays allocated; entries past the count are unused */
    memcpy(s->sky_color, sky_color, sizeof sky_color);
    s->sky_intensity = sky_intensity;
    s->has_camera = has_camera;
    memcpy(s->camera_pos, camera_pos, sizeof camera_pos);
    memcpy(s->camera_target, camera_target, sizeof camera_target);
    s->camera_fov_deg = camera_fov_deg;
    s->ao_radius = ao_radius;
    return SCENE_OK;
}

/* Writes "prefix/suffix" (or prefix alone when suffix is NULL) into out, cut short to fit: names are for
 * messages only. */
static void json_join_name(char *out, size_t cap, const char *prefix, const char *suffix)
{
    size_t used = 0;
    const char *parts[3] = {prefix, suffix ? "/" : NULL, suffix};
    for (int p = 0; p < 3; p++)
        for (const char *c = parts[p]; c && *c && used + 1 < cap; c++)
            out[used++] = *c;
    out[used] = 0;
}

/* Imports one checked mesh entry: the material override (and its texture), the file, then the names. */
static scene_result json_import_entry(const json_ctx *ctx, scene *s, json_mesh_entry *entry,
                                      const char *where)
{
    if (entry->builtin)
        return json_add_builtin_default(ctx, s, entry->has_xform ? entry->xform : NULL, where);

    scene_result r;
    if (entry->has_texture) {
        int32_t texture = scene__add_texture(s, entry->texture, ctx->err);
        if (texture < 0) {
            char inner[sizeof ctx->err->msg];
            snprintf(inner, sizeof inner, "%s", ctx->err->msg);
            r = ctx->err->code != SCENE_OK ? ctx->err->code : SCENE_ERR_IO;
            return json_fail(ctx, r, where, "material.texture: %s", inner);
        }
        entry->material.texture = texture;
    }
    uint32_t first_mesh = s->mesh_count;
    scene__set_source(s, entry->file);
    r = scene__import_file(s, entry->file, entry->has_xform ? entry->xform : NULL,
                           entry->has_material ? &entry->material : NULL, ctx->err);
    if (r != SCENE_OK) {
        /* The importer names the mesh and vertex, not always the file: add the file when it is missing. */
        char inner[sizeof ctx->err->msg];
        snprintf(inner, sizeof inner, "%s", ctx->err->msg);
        if (strstr(inner, entry->file))
            return json_fail(ctx, r, where, "%s", inner);
        return json_fail(ctx, r, where, "%s: %s", entry->file, inner);
    }
    if (entry->has_name) {
        uint32_t added = s->mesh_count - first_mesh;
        for (uint32_t m = first_mesh; m < s->mesh_count; m++) {
            scene_mesh *mesh = &s->meshes[m];
            char original[sizeof mesh->name];
            memcpy(original, mesh->name, sizeof original);
            original[sizeof original - 1] = 0;
            if (added == 1)
                json_join_name(mesh->name, sizeof mesh->name, entry->name, NULL);
            else
                json_join_name(mesh->name, sizeof mesh->name, entry->name, original);
        }
    }
    return SCENE_OK;
}

/* Reads the "meshes" array: checks every entry, then imports them in order. */
static scene_result json_read_meshes(const json_ctx *ctx, scene *s, const json_t *meshes)
{
    if (!json_is_array(meshes))
        return json_fail(ctx, SCENE_ERR_JSON, "meshes", "must be an array, not %s", json_type_word(meshes));
    size_t count = json_array_size(meshes);
    if (count == 0)
        return json_fail(ctx, SCENE_ERR_EMPTY, "meshes", "is empty: a scene needs at least one mesh");
    json_mesh_entry *entries = calloc(count, sizeof *entries); /* calloc checks count * size for overflow */
    if (!entries)
        return json_fail(ctx, SCENE_ERR_NOMEM, "meshes", "out of memory for %zu entries", count);
    scene_result r = SCENE_OK;
    char where[JSON_WHERE_CAP];
    for (size_t i = 0; i < count && r == SCENE_OK; i++) {
        json_element_path(where, sizeof where, "meshes", i);
        r = json_read_mesh_entry(ctx, json_array_get(meshes, i), where, &entries[i]);
    }
    for (size_t i = 0; i < count && r == SCENE_OK; i++) {
        json_element_path(where, sizeof where, "meshes", i);
        r = json_import_entry(ctx, s, &entries[i], where);
    }
    free(entries);
    return r;
}

/* Reads the whole description (root, already parsed) into s. */
static scene_result json_read_root(const json_ctx *ctx, scene *s, const json_t *root)
{
    if (!json_is_object(root))
        return json_fail(ctx, SCENE_ERR_JSON, NULL, "the top level must be an object, not %s",
                         json_type_word(root));
    static const char *const allowed[] = {"version",       "meshes",    "lights",  "sky",
                                          "texel_density", "ao_radius", "effects", "camera"};
    scene_result r = json_check_object(ctx, root, "", allowed, sizeof allowed / sizeof allowed[0]);
    if (r != SCENE_OK)
        return r;

    const json_t *version = json_object_get(root, "version");
    if (!version)
        return json_fail(ctx, SCENE_ERR_JSON, NULL,
                         "missing required field 'version' (this fxcache reads %d)", JSON_SCENE_VERSION);
    if (!json_is_integer(version))
        return json_fail(ctx, SCENE_ERR_JSON, "version", "must be an integer, not %s",
                         json_type_word(version));
    json_int_t version_number = json_integer_value(version);
    if (version_number > JSON_SCENE_VERSION)
        return json_fail(ctx, SCENE_ERR_FORMAT, "version",
                         "%lld is newer than this fxcache supports (%d): update fxcache",
                         (long long)version_number, JSON_SCENE_VERSION);
    if (version_number < 1)
        return json_fail(ctx, SCENE_ERR_INVALID, "version", "must be %d (it is %lld)", JSON_SCENE_VERSION,
                         (long long)version_number);

    const json_t *meshes = json_object_get(root, "meshes");
    if (!meshes)
        return json_fail(ctx, SCENE_ERR_JSON, NULL, "missing required field 'meshes'");

    const json_t *lights = json_object_get(root, "lights");
    if (lights && (r = json_read_lights(ctx, s, lights)) != SCENE_OK)
        return r;
    const json_t *sky = json_object_get(root, "sky");
    if (sky && (r = json_read_sky(ctx, s, sky)) != SCENE_OK)
        return r;
    if ((r = json_read_density_and_radius(ctx, s, root)) != SCENE_OK)
        return r;
    const json_t *effects = json_object_get(root, "effects");
    if (effects) {
        static const char *const allowed_effects[] = {"shadows", "ao", "indirect"};
        if ((r = json_check_object(ctx, effects, "effects", allowed_effects, 3)) != SCENE_OK ||
            (r = json_read_toggle(ctx, effects, "shadows", &s->fx_shadows)) != SCENE_OK ||
            (r = json_read_toggle(ctx, effects, "ao", &s->fx_ao)) != SCENE_OK ||
            (r = json_read_toggle(ctx, effects, "indirect", &s->fx_indirect)) != SCENE_OK)
            return r;
    }
    const json_t *camera = json_object_get(root, "camera");
    if (camera && (r = json_read_camera(ctx, s, camera)) != SCENE_OK)
        return r;
    return json_read_meshes(ctx, s, meshes);
}

/* Reads a JSON scene description at path into s (fresh from scene__alloc). On failure err names the file and
 * the line and column (malformed JSON) or the JSON path at fault; s may then hold part of the scene and the
 * caller frees it. */
scene_result scene__load_json(scene *s, const char *path, scene_error *err)
{
    json_ctx ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.path = path;
    ctx.err = err;
    const char *slash = strrchr(path, '/');
    if (slash) {
        size_t dir_length = (size_t)(slash - path) + 1;
        if (dir_length >= sizeof ctx.dir)
            return scene__fail(err, SCENE_ERR_IO, "%s: the folder name is too long", path);
        memcpy(ctx.dir, path, dir_length);
        ctx.dir[dir_length] = 0;
    }

    /* A UTF-8 byte-order mark (editors on Windows write one) is skipped, as the trace reader does: RFC 8259
     * lets a parser ignore it, jansson refuses it ("'[' or '{' expected near '\xef\xbb\xbf'"). */
    FILE *file = fopen(path, "rb");
    if (!file)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    unsigned char bom[3];
    if (!(fread(bom, 1, 3, file) == 3 && bom[0] == 0xef && bom[1] == 0xbb && bom[2] == 0xbf))
        rewind(file);
    json_error_t parse_error;
    json_t *root = json_loadf(file, JSON_REJECT_DUPLICATES, &parse_error);
    fclose(file);
    if (!root) {
        if (json_error_code(&parse_error) == json_error_cannot_open_file)
            return scene__fail(err, SCENE_ERR_IO, "%s: %s", path, parse_error.text);
        if (json_error_code(&parse_error) == json_error_out_of_memory)
            return scene__fail(err, SCENE_ERR_NOMEM, "%s: %s", path, parse_error.text);
        return scene__fail(err, SCENE_ERR_JSON, "%s:%d:%d: %s", path, parse_error.line, parse_error.column,
                           parse_error.text);
    }
    scene_result r = json_read_root(&ctx, s, root);
    json_decref(root);
    return r;
}

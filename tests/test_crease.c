/* Crease tests (effects/): sample points of texels and pixels where two surfaces meet.
 *
 * A texel or pixel beside a crease (a floor meeting a wall) must sample its own surface only: never a point
 * on the wall's plane, where a ray with tnear = 0 meets the wall at t = 0 whatever its direction (AO 0), and
 * never a point behind the wall, where light comes in that cannot reach the floor. Expectations are closed
 * forms:
 *   - AO: a cosine-weighted direction projects to a uniform point (x, z) of the unit disk (Malley); a ray of
 *     length R from a floor point at distance d from a wall meets the wall iff its component towards the
 *     wall exceeds d / R, and meets a ceiling at height h iff its vertical component sqrt(1 - x^2 - z^2)
 *     exceeds h / R, i.e. iff x^2 + z^2 < rho^2 = 1 - (h / R)^2 (a ray meeting the wall's plane above h has
 *     met the ceiling first). So the unoccluded fraction is the area of the unit disk with x > -d1 / R and
 *     z > -d2 / R, less that of the disk of radius rho with the same bounds (rho^2 times the unit disk's with
 *     bounds d / (R rho)), over pi (disk_open; checked against counting grid cells);
 *   - shadows: inside a closed box, or in a closed room behind a 1 mm wall, no ray reaches the sun.
 * Cached AO (fx_lookup_update, then fx_ao_update to 64 samples on every block of the floor) is compared per
 * group of texels at one distance from the crease, averaged along it, each group with 32 x 64 samples or more
 * (more seeds for the few texels of a corner); a texel's expectation is the closed form averaged over its
 * footprint, the part beyond the floor's edge moved onto the edge (where the effect's points go). Bilinear
 * reads on and near the crease, as compose reads, are compared too. Rooms are moved off the origin, and the
 * shadow rooms also turned, so that points on a crease round to either side of the wall.
 *
 * Before the fix (6409b8d), at 37 texels per metre and R = 4 m: the level-0 texel beyond a crease held AO
 * 0.00 (closed form 0.50), a bilinear read on the crease 0.23 to 0.25 and 15 mm from it 0.40; the level-3
 * texel across a crease 0.28 (0.50); the no-cache AO exactly on a crease 0.00; turned boxes had lit texels
 * along their creases, and no-cache footprints reaching past a wall were lit up to 14/16. */
#include "test_util.h"

#include "fxt_scene.h"

#include "effects.h"
#include "fx_internal.h"
#include "scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- scene building (as in test_effects.c) -------------------------------------------------------- */

/* Where a test room goes: world = rot * room + shift. */
typedef struct placement {
    double rot[3][3];
    double shift[3];
} placement;

/* rot * v (+ shift when `point`). */
static void place(const placement *pl, const double v[3], bool point, double out[3])
{
    for (int r = 0; r < 3; r++)
        out[r] =
            pl->rot[r][0] * v[0] + pl->rot[r][1] * v[1] + pl->rot[r][2] * v[2] + (point ? pl->shift[r] : 0.0);
}

/* The same as floats. */
static void place_float(const placement *pl, const double v[3], bool point, float out[3])
{
    double world[3];
    place(pl, v, point, world);
    for (int k = 0; k < 3; k++)
        out[k] = (float)world[k];
}

/* Adds a rectangle of the room, placed by pl: `axis` is the constant coordinate (0 x, 1 y, 2 z) at `at`,
 * spanning [lo, hi] in the other two (in x, y, z order), facing +axis when facing > 0 else -axis. */
static void add_rect(scene *s, const char *name, const placement *pl, int axis, double at, const double lo[2],
                     const double hi[2], int facing, uint32_t cells)
{
    int a = (axis + 1) % 3, b = (axis + 2) % 3; /* e_a x e_b = +e_axis */
    double corner[3], edge_a[3] = {0, 0, 0}, edge_b[3] = {0, 0, 0};
    /* lo/hi are given in x, y, z order of the two free axes. */
    int first = a < b ? a : b;
    double lo_a = a == first ? lo[0] : lo[1], hi_a = a == first ? hi[0] : hi[1];
    double lo_b = b == first ? lo[0] : lo[1], hi_b = b == first ? hi[0] : hi[1];
    corner[axis] = at;
    corner[a] = lo_a;
    corner[b] = lo_b;
    edge_a[a] = hi_a - lo_a;
    edge_b[b] = hi_b - lo_b;
    double world_corner[3], world_a[3], world_b[3];
    place(pl, corner, true, world_corner);
    place(pl, edge_a, false, world_a);
    place(pl, edge_b, false, world_b);
    if (facing > 0)
        fxt_add_quad(s, name, world_corner, world_a, world_b, cells);
    else
        fxt_add_quad(s, name, world_corner, world_b, world_a, cells);
}

/* ---- running an effect over a whole island -------------------------------------------------------- */

/* The affine map from level-0 island UV to world of a planar island, from its first triangle (computed here
 * in double, independently of the effect code): world = origin + u * along_u + v * along_v. */
typedef struct uv_to_world {
    double origin[3], along_u[3], along_v[3];
} uv_to_world;

static uv_to_world island_plane_map(const scene *s, uint32_t island)
{
    uint32_t tri = s->island_triangles[s->islands[island].first];
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    const uint32_t *corner = s->indices + 3 * (size_t)tri;
    double e1u = (double)uv[2] - uv[0], e1v = (double)uv[3] - uv[1];
    double e2u = (double)uv[4] - uv[0], e2v = (double)uv[5] - uv[1];
    double det = e1u * e2v - e1v * e2u;
    assert_true(fabs(det) > 0);
    uv_to_world map;
    for (int k = 0; k < 3; k++) {
        double p0 = s->positions[3 * (size_t)corner[0] + k];
        double w1 = s->positions[3 * (size_t)corner[1] + k] - p0,
               w2 = s->positions[3 * (size_t)corner[2] + k] - p0;
        /* world offset = a * e1 + b * e2 where (du, dv) = a * e1uv + b * e2uv */
        map.along_u[k] = (w1 * e2v - w2 * e1v) / det;
        map.along_v[k] = (-w1 * e2u + w2 * e1u) / det;
        map.origin[k] = p0 - map.along_u[k] * uv[0] - map.along_v[k] * uv[1];
    }
    return map;
}

static void uv_world(const uv_to_world *map, double u, double v, double out[3])
{
    for (int k = 0; k < 3; k++)
        out[k] = map->origin[k] + u * map->along_u[k] + v * map->along_v[k];
}

/* ---- closed forms ----------------------------------------------------------------------------------- */

/* disk_open: fxt_disk_open (fxt_scene.c), shared with the stability suite. */
#define disk_open fxt_disk_open

/* The closed form against a second method: counting the cells of a fine grid over the unit disk. */
static void test_closed_form(void **state)
{
    (void)state;
    const double cases[][4] = {{INFINITY, INFINITY, INFINITY, 4},
                               {0, INFINITY, INFINITY, 4},
                               {0, 0, INFINITY, 4},
                               {0.3, 0.7, INFINITY, 4},
                               {1.5, 2.5, 2.5, 4},
                               {0, 0, 2.5, 4},
                               {0.2, INFINITY, 1.0, 4},
                               {5, 0.1, 3.9, 4}};
    const int n = 2000;
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        double a = cases[c][0] / cases[c][3], b = cases[c][1] / cases[c][3], hr = cases[c][2] / cases[c][3];
        long inside = 0, open = 0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double x = -1 + (i + 0.5) * 2.0 / n, z = -1 + (j + 0.5) * 2.0 / n, r2 = x * x + z * z;
                if (r2 >= 1)
                    continue;
                inside++;
                open += x > -a && z > -b && !(sqrt(1 - r2) > hr);
            }
        double counted = (double)open / (double)inside,
               closed = disk_open(cases[c][0], cases[c][1], cases[c][2], cases[c][3]);
        assert_true(fabs(counted - closed) < 2e-3);
    }
    assert_true(fabs(disk_open(0, INFINITY, INFINITY, 4) - 0.5) < 1e-12);
    assert_true(fabs(disk_open(0, 0, INFINITY, 4) - 0.25) < 1e-12);
}

/* ---- AO at creases ---------------------------------------------------------------------------------- */

/* Where the test rooms go: moved so that no crease lies at a coordinate of 0 (where floats are dense and
 * clamped points land on the wall's side only by luck), and also turned (27 degrees about y, then 8 about x),
 * so that points on a crease round to either side of the wall's plane. */
static const placement ROOM = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {2.7, 0.85, -1.9}};
static const placement TURNED = {{{0.8910065242, 0, 0.4539904997},
                                  {0.0631832657, 0.9902680687, -0.1240041409},
                                  {-0.4495722954, 0.1391731010, 0.8823353099}},
                                 {-3.3, 1.45, 6.1}};
static const double *const ROOM_SHIFT = ROOM.shift;

/* Tolerance of every AO comparison (the report's defect: 0.25 for 0.50 at the contact). */
#define AO_TOLERANCE 0.03

/* A room corner (before ROOM_SHIFT): the floor y = 0 over x in [0, floor_x], z in [z0, z1]; a wall x = 0
 * facing +x; optionally a wall z = 0 facing +z (then z0 = 0) and a ceiling y = ceiling facing down; walls and
 * ceiling reach beyond every ray of length radius from the floor. */
typedef struct corner_setup {
    double floor_x, z0, z1;
    bool wall_z;
    double ceiling; /* INFINITY: none */
} corner_setup;

static scene *corner_room(const corner_setup *c, float density, float radius, scene_rt **rt)
{
    scene *s = fxt_new_scene();
    double reach = radius + 1.0, top = isinf(c->ceiling) ? reach : c->ceiling;
    add_rect(s, "floor", &ROOM, 1, 0, (double[2]){0, c->z0}, (double[2]){c->floor_x, c->z1}, +1, 2);
    add_rect(s, "wall_x", &ROOM, 0, 0, (double[2]){0, c->z0 - reach}, (double[2]){top, c->z1 + reach}, +1, 2);
    if (c->wall_z)
        add_rect(s, "wall_z", &ROOM, 2, 0, (double[2]){0, 0}, (double[2]){c->floor_x + reach, top}, +1, 2);
    if (!isinf(c->ceiling))
        add_rect(s, "ceiling", &ROOM, 1, c->ceiling, (double[2]){0, c->z0 - reach},
                 (double[2]){c->floor_x + reach, c->z1 + reach}, -1, 2);
    *rt = fxt_finish_scene(s, density, radius);
    return s;
}

/* The closed form at room point (x, z) of the floor (distances from the walls). */
static double corner_open(const corner_setup *c, double x, double z, double radius)
{
    return disk_open(x, c->wall_z ? z : INFINITY, c->ceiling, radius);
}

/* Room x and z (unshifted) of level-0 island UV (u, v) of the floor. */
static void floor_xz(const uv_to_world *map, double u, double v, double *x, double *z)
{
    double p[3];
    uv_world(map, u, v, p);
    *x = p[0] - ROOM_SHIFT[0];
    *z = p[2] - ROOM_SHIFT[2];
}

/* Level-0 island UV of room floor point (x, z): the map inverted on the floor plane. */
static void floor_uv(const uv_to_world *map, double x, double z, double *u, double *v)
{
    double dx = x + ROOM_SHIFT[0] - map->origin[0], dz = z + ROOM_SHIFT[2] - map->origin[2];
    double a = map->along_u[0], b = map->along_v[0], c = map->along_u[2], d = map->along_v[2];
    double det = a * d - b * c;
    *u = (dx * d - b * dz) / det;
    *v = (a * dz - c * dx) / det;
}

/* The expected AO of a floor texel: the closed form averaged over an 8 x 8 grid of its footprint, with the
 * part beyond the floor's edges moved onto the edge (where the effect's sample points go). */
static double texel_expectation(const corner_setup *c, const uv_to_world *map, uint32_t level, uint32_t tx,
                                uint32_t ty, float radius)
{
    double sum = 0, scale = (double)(1u << level);
    for (int j = 0; j < 8; j++)
        for (int i = 0; i < 8; i++) {
            double x, z;
            floor_xz(map, (tx + (i + 0.5) / 8) * scale, (ty + (j + 0.5) / 8) * scale, &x, &z);
            sum += corner_open(c, fmin(fmax(x, 0.0), c->floor_x), fmin(fmax(z, c->z0), c->z1), radius);
        }
    return sum / 64;
}

/* Groups whose AO is compared as a mean (64 samples of one texel are too few for 0.03): by the distance of
 * the texel centre from the wall x = 0 in texels (0: the centre lies beyond the floor's edge, 1: within the
 * first texel, ...); with a second wall, the 3 x 3 texels of the corner each alone and the others by the
 * distance from the nearer wall. */
enum { GROUPS = 140, GROUP_CORNER = 128 };

static int texel_group(const corner_setup *c, double x, double z, double texel_m)
{
    int bx = x < 0 ? 0 : 1 + (int)fmin(floor(x / texel_m), 62);
    if (!c->wall_z)
        return bx;
    int bz = z < 0 ? 0 : 1 + (int)fmin(floor(z / texel_m), 62);
    if (bx < 3 && bz < 3)
        return GROUP_CORNER + 3 * bx + bz;
    return bx <= bz ? bx : 64 + bz;
}

/* Level-0 texels of an island at level l, rounded up. */
static uint32_t island_texels(uint32_t size, uint32_t level)
{
    return (size + (1u << level) - 1) >> level;
}

/* The four texel slots (block * 64 + texel) and weights of a bilinear read of island run at level-0 island UV
 * (u, v), as compose reads: texel centres at (i + 0.5) 2^level, indices clamped into the island. */
static void bilinear_taps(const scene *s, const fxt_island_run *run, double u, double v, size_t slots[4],
                          double weights[4])
{
    double scale = (double)(1u << run->level), fu = u / scale - 0.5, fv = v / scale - 0.5;
    int i0 = (int)floor(fu), j0 = (int)floor(fv);
    double a = fu - i0, b = fv - j0;
    int width = (int)island_texels(s->islands[run->island].width, run->level);
    int height = (int)island_texels(s->islands[run->island].height, run->level);
    for (int tap = 0; tap < 4; tap++) {
        int di = tap & 1, dj = tap >> 1, i = i0 + di, j = j0 + dj;
        i = i < 0 ? 0 : (i >= width ? width - 1 : i);
        j = j < 0 ? 0 : (j >= height ? height - 1 : j);
        slots[tap] = ((size_t)(j / 8) * run->blocks_x + (size_t)(i / 8)) * 64 + (size_t)((j % 8) * 8 + i % 8);
        weights[tap] = (di ? a : 1 - a) * (dj ? b : 1 - b);
    }
}

/* What check_cached_ao measured, for the report. */
typedef struct cached_result {
    double worst;               /* largest |mean - closed form| over the groups and the bilinear reads */
    double contact, closed;     /* group of the texel on the crease: mean AO and closed form */
    double read0, read0_texels; /* bilinear read exactly on the crease (x = 0), mean along it, and the same
                                   read of the texels' closed forms */
    double read0_point;         /* the closed form on the crease itself */
} cached_result;

/* Cached AO of a corner room's floor at level, seed by seed until every group has 32 x 64 samples or more
 * (fx_lookup_update then fx_ao_update to 64 samples over every block of the floor, as frame stages 5 and 6
 * do), against the closed form per group; then bilinear reads along the crease x = 0. */
static cached_result check_cached_ao(const corner_setup *c, float density, float radius, uint32_t level,
                                     const char *what)
{
    scene_rt *rt;
    scene *s = corner_room(c, density, radius, &rt);
    uint32_t island = fxt_island_of_mesh(s, 0);
    uv_to_world map = island_plane_map(s, island);
    fxt_island_run run, extra;
    fxt_island_run_init(&run, s, island, level, FX_AO);
    fxt_island_run_init(&extra, s, island, level, FX_AO);
    double texel_m = (double)(1u << level) / density, scale = (double)(1u << level);

    /* Each texel's group and expectation. */
    size_t texel_slots = (size_t)run.block_count * 64;
    int *group = malloc(sizeof(int) * texel_slots);
    double *expected = malloc(sizeof(double) * texel_slots);
    assert_true(group && expected);
    uint32_t members[GROUPS] = {0};
    for (uint32_t b = 0; b < run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++) {
            size_t slot = (size_t)b * 64 + t;
            group[slot] = -1;
            if (!(run.jobs[b].mask >> t & 1))
                continue;
            uint32_t tx = run.jobs[b].block_x * 8 + (t & 7), ty = run.jobs[b].block_y * 8 + (t >> 3);
            double x, z;
            floor_xz(&map, (tx + 0.5) * scale, (ty + 0.5) * scale, &x, &z);
            group[slot] = texel_group(c, x, z, texel_m);
            expected[slot] = texel_expectation(c, &map, level, tx, ty, radius);
            members[group[slot]]++;
        }

    double measured_sum[GROUPS] = {0}, expected_sum[GROUPS] = {0};
    uint32_t samples[GROUPS] = {0};
    for (uint32_t seed = 0; seed < 32; seed++) {
        /* Seed 0 runs every texel (kept in `run` for the bilinear reads); later seeds only the texels of
         * groups still short of 32 texels' worth. */
        fxt_island_run *target = seed == 0 ? &run : &extra;
        uint64_t texels = 0;
        for (uint32_t b = 0; b < run.block_count; b++) {
            uint64_t mask = 0;
            for (uint32_t t = 0; t < 64; t++) {
                int g = group[(size_t)b * 64 + t];
                if (g >= 0 && (seed == 0 || members[g] * (seed + 1) <= 32))
                    mask |= 1ull << t;
            }
            target->jobs[b].mask = mask;
            texels += (uint64_t)__builtin_popcountll(mask);
        }
        if (texels == 0)
            break;
        memset(target->payload, 0, texel_slots * 4);
        fx_context ctx = {.s = s, .rt = rt, .seed = 101 + seed, .ao_radius = radius};
        assert_int_equal(fx_ao_update(&ctx, target->jobs, target->block_count, FX_AO_MAX_SAMPLES),
                         texels * FX_AO_MAX_SAMPLES);
        for (uint32_t b = 0; b < run.block_count; b++)
            for (uint64_t bits = target->jobs[b].mask; bits; bits &= bits - 1) {
                uint32_t t = (uint32_t)__builtin_ctzll(bits);
                size_t slot = (size_t)b * 64 + t;
                assert_int_equal(fx_ao_count(target->jobs[b].payload, t), FX_AO_MAX_SAMPLES);
                measured_sum[group[slot]] += fx_ao_sample(target->jobs[b].payload, t);
                expected_sum[group[slot]] += expected[slot];
                samples[group[slot]]++;
            }
    }

    cached_result result = {.worst = 0, .contact = NAN, .closed = NAN};
    uint32_t groups_seen = 0;
    for (int g = 0; g < GROUPS; g++) {
        if (!samples[g])
            continue;
        groups_seen++;
        double m = measured_sum[g] / samples[g], e = expected_sum[g] / samples[g];
        result.worst = fmax(result.worst, fabs(m - e));
        int contact_group = c->wall_z ? GROUP_CORNER : 0;
        if (isnan(result.contact) && (g == contact_group || g == contact_group + (c->wall_z ? 4 : 1))) {
            result.contact = m; /* the outermost texel on the crease (beyond the edge if there is one) */
            result.closed = e;
        }
        if (fabs(m - e) > AO_TOLERANCE || g <= 2 || g == GROUP_CORNER || g == GROUP_CORNER + 4)
            printf("    %s level %u group %d (%u texels x 64): AO %.4f, closed form %.4f\n", what, level, g,
                   samples[g], m, e);
    }
    assert_true(groups_seen >= 3);

    /* Bilinear reads along the crease x = 0 and at distances from it, as compose reads them, against the same
     * reads of the texels' closed forms (a texel of level 3 at 10 texels per metre is 0.8 m wide: its reads
     * are smooth, and the point's own closed form is printed beside). */
    const double distances[] = {0, 0.005, 0.015, 0.027, 0.05, 0.1, 0.3};
    for (size_t i = 0; i < sizeof distances / sizeof distances[0]; i++) {
        if (distances[i] > c->floor_x - 2 * texel_m)
            break;
        double read = 0, read_texels = 0, closed = 0;
        const int points = 200;
        for (int k = 0; k < points; k++) {
            double z = c->z0 + (c->z1 - c->z0) * (k + 0.5) / points, u, v, weights[4];
            size_t slots[4];
            floor_uv(&map, distances[i], z, &u, &v);
            bilinear_taps(s, &run, u, v, slots, weights);
            for (int tap = 0; tap < 4; tap++) {
                assert_true(group[slots[tap]] >= 0);
                read += weights[tap] *
                        fx_ao_sample(run.payload + 4 * slots[tap] - 4 * (slots[tap] % 64), slots[tap] % 64);
                read_texels += weights[tap] * expected[slots[tap]];
            }
            closed += corner_open(c, distances[i], z, radius);
        }
        read /= points;
        read_texels /= points;
        closed /= points;
        if (i == 0) {
            result.read0 = read;
            result.read0_texels = read_texels;
            result.read0_point = closed;
        }
        printf("    %s level %u bilinear read at %.3f m: AO %.4f, texels' closed form %.4f (point %.4f)\n",
               what, level, distances[i], read, read_texels, closed);
        result.worst = fmax(result.worst, fabs(read - read_texels));
    }
    free(group);
    free(expected);
    fxt_island_run_free(&extra);
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
    return result;
}

/* The floor's extent for a level and density: up to 3 m (x) by 12 m (z), at most 48 x 96 texels. */
static void floor_extent(float density, uint32_t level, double *x, double *z)
{
    double texel_m = (double)(1u << level) / density;
    *x = fmin(3.0, 48 * texel_m);
    *z = fmin(12.0, 96 * texel_m);
}

/* Cached AO of a floor beside one wall, in a corner of two walls, and in that corner under a ceiling, at
 * levels 0 and 3, at the report's density (37 texels per metre: a level-0 texel of 27 mm) and at 10 and 100.
 */
static void test_ao_crease_cached(void **state)
{
    (void)state;
    const float densities[] = {37.0f, 10.0f, 100.0f};
    const float radius = 4.0f;
    for (size_t d = 0; d < sizeof densities / sizeof densities[0]; d++)
        for (uint32_t level = 0; level <= 3; level += 3)
            for (int kind = 0; kind < 4; kind++) {
                double fx, fz;
                floor_extent(densities[d], level, &fx, &fz);
                corner_setup c = {.floor_x = fx, .z0 = -fz / 2, .z1 = fz / 2, .ceiling = INFINITY};
                const char *what = "wall";
                if (kind == 1) {
                    /* A floor of a width that is no whole number of texels: its edges, the crease among them,
                     * cross texels (at 37 per metre, 30 % of a level-0 and 1/3 of a level-3 texel inside). */
                    c.floor_x *= 0.967;
                    what = "wall, odd floor";
                }
                if (kind >= 2) {
                    c.wall_z = true;
                    c.z0 = 0;
                    c.z1 = fx;
                    what = "corner";
                }
                if (kind == 3) {
                    c.ceiling = 2.5;
                    what = "corner+ceiling";
                }
                printf("  %s, density %.0f, level %u:\n", what, densities[d], level);
                cached_result r = check_cached_ao(&c, densities[d], radius, level, what);
                printf("  %s, density %.0f, level %u: contact texel AO %.4f (closed form %.4f), read on the "
                       "crease "
                       "%.4f (texels %.4f, point %.4f), worst error %.4f\n",
                       what, densities[d], level, r.contact, r.closed, r.read0, r.read0_texels, r.read0_point,
                       r.worst);
                assert_true(r.worst <= AO_TOLERANCE);
            }
}

/* The no-cache AO at floor points at distances d1 from the wall x = 0 (and d2 from the wall z = 0), d = 0
 * exactly on the crease, each averaged over 256 pixels (seeds); along the crease for the one-wall room. */
static void test_ao_crease_no_cache(void **state)
{
    (void)state;
    const float radius = 4.0f;
    const double distances[] = {0, 1e-5, 1e-3, 0.005, 0.015, 0.027, 0.1, 0.5, 1.5};
    const size_t count = sizeof distances / sizeof distances[0];
    for (int kind = 0; kind < 3; kind++) {
        corner_setup c = {
            .floor_x = 3, .z0 = -6, .z1 = 6, .wall_z = kind > 0, .ceiling = kind == 2 ? 2.5 : INFINITY};
        if (c.wall_z) {
            c.z0 = 0;
            c.z1 = 3;
        }
        scene_rt *rt;
        scene *s = corner_room(&c, 37.0f, radius, &rt);
        fx_context ctx = {.s = s, .rt = rt, .seed = 3, .ao_radius = radius};
        double worst = 0;
        for (size_t i = 0; i < count; i++)
            for (size_t j = 0; j < (c.wall_z ? count : 1); j++) {
                double sum = 0, closed = 0;
                const uint32_t pixels = 256;
                for (uint32_t p = 0; p < pixels; p++) {
                    double z = c.wall_z ? distances[j] : -5.0 + 10.0 * (p + 0.5) / pixels;
                    float pos[3] = {(float)(ROOM_SHIFT[0] + distances[i]), (float)ROOM_SHIFT[1],
                                    (float)(ROOM_SHIFT[2] + z)};
                    uint64_t rays = 0;
                    sum += fx_ao_eval_point(&ctx, pos, (float[3]){0, 1, 0}, FX_AO_MAX_SAMPLES, p, &rays);
                    assert_int_equal(rays, FX_AO_MAX_SAMPLES);
                    closed += corner_open(&c, distances[i], z, radius);
                }
                double mean = sum / pixels, expected = closed / pixels;
                if (j == 0 || fabs(mean - expected) > AO_TOLERANCE)
                    printf("    no-cache %s d %.5f (d2 %.5f): AO %.4f, closed form %.4f\n",
                           kind == 0 ? "wall" : (kind == 1 ? "corner" : "corner+ceiling"), distances[i],
                           c.wall_z ? distances[j] : INFINITY, mean, expected);
                worst = fmax(worst, fabs(mean - expected));
            }
        printf("  no-cache %s: worst error %.4f\n",
               kind == 0 ? "wall" : (kind == 1 ? "corner" : "corner+ceiling"), worst);
        assert_true(worst <= AO_TOLERANCE);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* ---- shadows at creases ------------------------------------------------------------------------------ */

/* Lit bits and traced rays of every texel of mesh's island at level for light 0 (one light). */
typedef struct shadow_count {
    uint64_t texels, lit_texels, lit_bits, rays;
} shadow_count;

static shadow_count cached_shadow(const scene *s, scene_rt *rt, uint32_t mesh, uint32_t level)
{
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, mesh), level, FX_SHADOW);
    memset(run.payload, 0xa5, (size_t)run.block_count * 64 * run.texel_bytes); /* must be overwritten */
    fx_context ctx = {.s = s, .rt = rt, .seed = 9, .ao_radius = 1.0f};
    shadow_count count = {.texels = run.texels};
    count.rays = fx_shadow_update(&ctx, run.jobs, run.block_count);
    for (uint32_t b = 0; b < run.block_count; b++)
        for (uint64_t bits = run.jobs[b].mask; bits; bits &= bits - 1) {
            uint32_t t = (uint32_t)__builtin_ctzll(bits);
            uint16_t mask = (uint16_t)fx__get_u16((const uint8_t *)run.jobs[b].payload + 2 * t);
            count.lit_bits += (uint64_t)__builtin_popcount(mask);
            count.lit_texels += mask != 0;
        }
    fxt_island_run_free(&run);
    return count;
}

/* No-cache shadows at a grid of points of a room face placed by pl: constant coordinate `axis` at `at`, the
 * other two (a < b in x, y, z order) over [lo, hi] including both ends exactly and points 1e-5 m and 1e-3 m
 * inside them; normal and footprint differentials given in room coordinates (in the face's plane). Returns
 * the largest lit fraction; counts the calls and rays. */
static double no_cache_face(const fx_context *ctx, const placement *pl, int axis, double at,
                            const double lo[2], const double hi[2], const double normal[3],
                            const double dpdx[3], const double dpdy[3], uint64_t *calls, uint64_t *rays)
{
    int a = axis == 0 ? 1 : 0, b = axis == 2 ? 1 : 2;
    float world_normal[3], world_dpdx[3], world_dpdy[3];
    place_float(pl, normal, false, world_normal);
    place_float(pl, dpdx, false, world_dpdx);
    place_float(pl, dpdy, false, world_dpdy);
    double worst = 0;
    const double fractions[] = {0, 1e-5, 1e-3, 0.01, 0.05, 0.2, 0.5};
    const size_t n = sizeof fractions / sizeof fractions[0];
    for (size_t i = 0; i < 2 * n; i++)
        for (size_t j = 0; j < 2 * n; j++) {
            double p[3];
            /* the first half from lo upwards, the second from hi downwards (in metres for the tiny ones) */
            double fa = fractions[i % n], fb = fractions[j % n];
            double da = fa < 0.01 ? fa : fa * (hi[0] - lo[0]), db = fb < 0.01 ? fb : fb * (hi[1] - lo[1]);
            p[axis] = at;
            p[a] = i < n ? lo[0] + da : hi[0] - da;
            p[b] = j < n ? lo[1] + db : hi[1] - db;
            double world[3];
            float pos[3];
            place(pl, p, true, world);
            scene_world_to_local(ctx->s, world, pos); /* the scene may be rebased onto its centre */
            uint64_t r = 0;
            double lit =
                fx_shadow_eval_point(ctx, pos, world_normal, world_dpdx, world_dpdy, 0, i * 64 + j, &r);
            worst = fmax(worst, lit);
            *calls += 1;
            *rays += r;
        }
    return worst;
}

/* Adds a sun travelling along room direction (dx, dy, dz), placed by pl. */
static void add_placed_sun(scene *s, const placement *pl, double dx, double dy, double dz)
{
    float dir[3];
    place_float(pl, (double[3]){dx, dy, dz}, false, dir);
    fxt_add_sun(s, dir[0], dir[1], dir[2]);
}

/* A closed box (2 x 1.5 x 1.7 m, faces inward) under a sun outside it, axis-aligned and turned: the floor and
 * two walls face the sun, and not one texel (levels 0 and 3) nor pixel (footprints of 0.3 m, reaching past
 * the walls, and of 3 m, past the opposite ones) inside is lit. */
static void test_shadow_closed_box(void **state)
{
    (void)state;
    const double w = 2.0, h = 1.5, d = 1.7;
    const float densities[] = {37.0f, 11.0f, 100.0f};
    const placement *placements[] = {&ROOM, &TURNED};
    for (size_t k = 0; k < sizeof densities / sizeof densities[0]; k++)
        for (int turned = 0; turned < 2; turned++) {
            const placement *pl = placements[turned];
            scene *s = fxt_new_scene();
            add_rect(s, "floor", pl, 1, 0, (double[2]){0, 0}, (double[2]){w, d}, +1, 2);
            add_rect(s, "ceiling", pl, 1, h, (double[2]){0, 0}, (double[2]){w, d}, -1, 2);
            add_rect(s, "wall x0", pl, 0, 0, (double[2]){0, 0}, (double[2]){h, d}, +1, 2);
            add_rect(s, "wall x1", pl, 0, w, (double[2]){0, 0}, (double[2]){h, d}, -1, 2);
            add_rect(s, "wall z0", pl, 2, 0, (double[2]){0, 0}, (double[2]){w, h}, +1, 2);
            add_rect(s, "wall z1", pl, 2, d, (double[2]){0, 0}, (double[2]){w, h}, -1, 2);
            add_placed_sun(s, pl, -0.4, -1.0,
                           -0.3); /* from above, +x, +z: faces the floor and walls x0, z0 */
            scene_rt *rt = fxt_finish_scene(s, densities[k], 1.0f);
            uint64_t facing_rays = 0, lit_bits = 0;
            for (uint32_t level = 0; level <= 3; level += 3)
                for (uint32_t mesh = 0; mesh < 6; mesh++) {
                    shadow_count count = cached_shadow(s, rt, mesh, level);
                    if (count.lit_texels)
                        printf(
                            "  box%s, density %.0f, level %u, mesh %u: %llu of %llu texels lit (%llu bits)\n",
                            turned ? " turned" : "", densities[k], level, mesh,
                            (unsigned long long)count.lit_texels, (unsigned long long)count.texels,
                            (unsigned long long)count.lit_bits);
                    lit_bits += count.lit_bits;
                    facing_rays += count.rays;
                }
            assert_int_equal(lit_bits, 0);
            assert_true(facing_rays > 1000); /* not vacuous: the three faces towards the sun were traced */

            fx_context ctx = {.s = s, .rt = rt, .seed = 5, .ao_radius = 1.0f};
            uint64_t calls = 0, rays = 0;
            const double footprints[] = {0.3, 3.0};
            double worst = 0;
            for (int f = 0; f < 2; f++) {
                double e = footprints[f];
                /* oblique differentials in each face's plane */
                worst = fmax(worst, no_cache_face(&ctx, pl, 1, 0, (double[2]){0, 0}, (double[2]){w, d},
                                                  (double[3]){0, 1, 0}, (double[3]){e, 0, 0.2 * e},
                                                  (double[3]){-0.15 * e, 0, e}, &calls, &rays));
                worst = fmax(worst, no_cache_face(&ctx, pl, 0, 0, (double[2]){0, 0}, (double[2]){h, d},
                                                  (double[3]){1, 0, 0}, (double[3]){0, e, 0.1 * e},
                                                  (double[3]){0, -0.2 * e, e}, &calls, &rays));
                worst = fmax(worst, no_cache_face(&ctx, pl, 2, 0, (double[2]){0, 0}, (double[2]){w, h},
                                                  (double[3]){0, 0, 1}, (double[3]){e, 0.3 * e, 0},
                                                  (double[3]){0, e, 0}, &calls, &rays));
            }
            printf(
                "  box%s, density %.0f: no-cache largest lit fraction %.4f over %llu pixels, %.2f rays per "
                "pixel\n",
                turned ? " turned" : "", densities[k], worst, (unsigned long long)calls,
                (double)rays / (double)calls);
            assert_true(worst == 0.0);
            assert_true(rays >=
                        calls * FX_SHADOW_RAYS); /* every pixel faces the sun: 16 shadow rays at least */
            scene_rt_free(rt);
            scene_free(s);
        }
}

/* Two rooms side by side, x < 0 open to the sky and x > T closed, separated by a wall of thickness T = 1 mm
 * (axis-aligned and turned); a low sun shines from the open room's side. No texel (levels 0 and 3) nor pixel
 * of the closed room is lit, pixels exactly on its creases included, while the open room's floor is. */
static void test_shadow_thin_wall(void **state)
{
    (void)state;
    const double t = 0.001, h = 2.5, d = 2.0, room = 2.0;
    const placement *placements[] = {&ROOM, &TURNED};
    for (int turned = 0; turned < 2; turned++) {
        const placement *pl = placements[turned];
        scene *s = fxt_new_scene();
        add_rect(s, "open floor", pl, 1, 0, (double[2]){-room, 0}, (double[2]){0, d}, +1, 2);         /* 0 */
        add_rect(s, "closed floor", pl, 1, 0, (double[2]){t, 0}, (double[2]){t + room, d}, +1, 2);    /* 1 */
        add_rect(s, "closed far wall", pl, 0, t + room, (double[2]){0, 0}, (double[2]){h, d}, -1, 2); /* 2 */
        add_rect(s, "closed wall z0", pl, 2, 0, (double[2]){0, 0}, (double[2]){t + room, h}, +1, 2);  /* 3 */
        add_rect(s, "closed wall z1", pl, 2, d, (double[2]){0, 0}, (double[2]){t + room, h}, -1, 2);  /* 4 */
        add_rect(s, "closed ceiling", pl, 1, h, (double[2]){t, 0}, (double[2]){t + room, d}, -1, 2);  /* 5 */
        add_rect(s, "partition, open side", pl, 0, 0, (double[2]){0, 0}, (double[2]){h, d}, -1, 2);   /* 6 */
        add_rect(s, "partition, closed side", pl, 0, t, (double[2]){0, 0}, (double[2]){h, d}, +1, 2); /* 7 */
        add_rect(s, "partition top", pl, 1, h, (double[2]){0, 0}, (double[2]){t, d}, +1, 1);          /* 8 */
        add_placed_sun(s, pl, 1.0, -0.8,
                       -0.25); /* travelling +x and down: from the open room to the closed */
        scene_rt *rt = fxt_finish_scene(s, 37.0f, 1.0f);

        for (uint32_t level = 0; level <= 3; level += 3) {
            for (uint32_t mesh = 1; mesh <= 7; mesh++) {
                if (mesh == 6)
                    continue; /* the partition's open side, facing the sun in the open room */
                shadow_count count = cached_shadow(s, rt, mesh, level);
                if (count.lit_texels)
                    printf("  thin wall%s, level %u, mesh %u: %llu of %llu texels lit\n",
                           turned ? " turned" : "", level, mesh, (unsigned long long)count.lit_texels,
                           (unsigned long long)count.texels);
                assert_int_equal(count.lit_bits, 0);
                if (mesh <= 3)
                    assert_true(count.rays > 0); /* the floor and two walls face the sun */
            }
            shadow_count open = cached_shadow(s, rt, 0, level);
            assert_true(open.lit_bits >= open.texels * FX_SHADOW_RAYS * 9 / 10); /* the open room is lit */
        }

        fx_context ctx = {.s = s, .rt = rt, .seed = 6, .ao_radius = 1.0f};
        uint64_t calls = 0, rays = 0;
        double worst = 0;
        const double footprints[] = {0.05, 0.3};
        for (int f = 0; f < 2; f++) {
            double e = footprints[f];
            worst = fmax(worst, no_cache_face(&ctx, pl, 1, 0, (double[2]){t, 0}, (double[2]){t + room, d},
                                              (double[3]){0, 1, 0}, (double[3]){e, 0, 0.1 * e},
                                              (double[3]){0.1 * e, 0, e}, &calls, &rays));
            worst = fmax(worst, no_cache_face(&ctx, pl, 2, 0, (double[2]){0, 0}, (double[2]){t + room, h},
                                              (double[3]){0, 0, 1}, (double[3]){e, 0.2 * e, 0},
                                              (double[3]){0, e, 0}, &calls, &rays));
        }
        printf("  thin wall%s: no-cache largest lit fraction %.4f over %llu pixels, %.2f rays per pixel\n",
               turned ? " turned" : "", worst, (unsigned long long)calls, (double)rays / (double)calls);
        assert_true(worst == 0.0);
        /* The open room's floor beside the wall is lit (the test is not vacuous). */
        float pos[3], up[3], dx[3], dz[3];
        double world[3];
        place(pl, (double[3]){-0.01, 0, 1.0}, true, world);
        scene_world_to_local(s, world, pos);
        place_float(pl, (double[3]){0, 1, 0}, false, up);
        place_float(pl, (double[3]){0.005, 0, 0}, false, dx);
        place_float(pl, (double[3]){0, 0, 0.005}, false, dz);
        assert_true(fx_shadow_eval_point(&ctx, pos, up, dx, dz, 0, 1, NULL) == 1.0f);
        scene_rt_free(rt);
        scene_free(s);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_closed_form),        cmocka_unit_test(test_ao_crease_cached),
        cmocka_unit_test(test_ao_crease_no_cache), cmocka_unit_test(test_shadow_closed_box),
        cmocka_unit_test(test_shadow_thin_wall),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}

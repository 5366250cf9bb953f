/* `fxcache serve`: the networked server. Viewers connect over WebSockets (the wire format is proto/, the
 * client viewer_client/), each with its own resolution and codec, and get frames for their latest camera at
 * --fps, composed by the same engine `fxcache sim` drives (the network is one more sink: server/net/).
 * SIGINT and SIGTERM stop it cleanly, within a tile of the frame in progress (which is abandoned): bye on
 * every connection, the statistics and the summary written, the recorded traces flushed. */
#include "cli.h"
#include "cli_engine.h"
#include "net.h"
#include "proto.h"

#include <errno.h>
#include <getopt.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static volatile sig_atomic_t stop_requested = 0;

/* Every signal asks for the end (the frame in progress is abandoned within a tile: srv_loop_set_stop): the
 * shutdown (bye to every viewer, the files) survives a supervisor's or a test's repeated SIGTERM. */
static void on_signal(int sig)
{
    stop_requested = sig;
}

typedef struct serve_options {
    srv_cli_engine engine;
    srv_net_desc net;
    const char *stats_path, *summary_path;
    uint32_t max_width, max_height;
    bool quiet;
    bool limits_set; /* --max-viewers or --max-res given */
} serve_options;

static const char serve_usage[] =
    "usage: fxcache serve [options]\n"
    "\n"
    "Serves composed frames to viewers over WebSockets (see docs/PROTOCOL.md; the client is\n"
    "fxcache-viewer). Viewers join and leave at any time, each with its own resolution and codec, and\n"
    "get frames for their latest camera at --fps; a slow viewer gets the newest frame (older ones are\n"
    "dropped and counted). hello's strategy picks the camera rendered: basic (the reported one), fan\n"
    "(tan(fov/2) x 1.5, same pixels) or predictive (the camera message's predicted pose, else a linear\n"
    "extrapolation); every frame carries the camera rendered. Sample requests (a client's render cache)\n"
    "are answered with exactly the pixels asked for, rendered through the same caches. Runs until SIGINT\n"
    "or SIGTERM (or --frames), then says bye to every viewer, writes the statistics and prints a summary.\n"
    "\n"
    "  --bind ADDR          IPv4 address of this machine to listen on, or a host name with one such as\n"
    "                       localhost (default 127.0.0.1; beyond 127.0.0.0/8 needs --token)\n"
    "  --port P             TCP port, 0..65535; 0 = any free port (default 7681). The address is\n"
    "                       printed on stdout as 'fxcache serve: listening on ws://ADDR:PORT'\n"
    "  --token T            access token every hello must carry (default: $FXCACHE_TOKEN, else none)\n"
    "  --fps F              frames per second, [0.001, 1000] (default 30)\n"
    "  --frames N           stop after N frames, 1..100000000 (default: until stopped); the clock\n"
    "                       starts with the first viewer's first camera\n"
    "  --max-viewers N      viewers at once, 1..64 (default 16)\n"
    "  --max-res WxH        largest resolution a viewer may ask for, sides 1..8192 (default 3840x2160)\n"
    "  --max-message B      largest message a viewer may send, bytes, 1024..16777216 (default 65536)\n"
    "  --camera-rate N      camera messages per second a viewer may send, 1..100000 (default 240);\n"
    "                       sample requests have a bucket of their own at the same rate\n"
    "  --max-samples N      pixels one sample request may ask for, 1..1048576 (default 65536); such a\n"
    "                       message may be 56 + 4 N bytes whatever --max-message says. The latest request\n"
    "                       is rendered in the next frame and answered with those pixels (docs/PROTOCOL.md)\n"
    "  --record DIR         write every viewer's rendered cameras as DIR/viewer_NN.trace with frame\n"
    "                       times; 'fxcache sim --trace ... --fps F' replays the session\n"
    "  --stats FILE         one JSON line of statistics per frame\n"
    "  --summary FILE       one JSON object at the end\n"
    "  --quiet              no summary in words on stdout\n";

static int parse_options(int argc, char **argv, serve_options *o)
{
    enum {
        O_BIND = SRV_CLI_O_COMMAND,
        O_PORT,
        O_TOKEN,
        O_FPS,
        O_FRAMES,
        O_MAXV,
        O_MAXRES,
        O_MAXMSG,
        O_RATE,
        O_RECORD,
        O_STATS,
        O_SUMMARY,
        O_QUIET,
        O_MAXSAMPLES
    };
    static const struct option own[] = {
        {"bind", required_argument, NULL, O_BIND},
        {"port", required_argument, NULL, O_PORT},
        {"token", required_argument, NULL, O_TOKEN},
        {"fps", required_argument, NULL, O_FPS},
        {"frames", required_argument, NULL, O_FRAMES},
        {"max-viewers", required_argument, NULL, O_MAXV},
        {"max-res", required_argument, NULL, O_MAXRES},
        {"max-message", required_argument, NULL, O_MAXMSG},
        {"camera-rate", required_argument, NULL, O_RATE},
        {"record", required_argument, NULL, O_RECORD},
        {"stats", required_argument, NULL, O_STATS},
        {"summary", required_argument, NULL, O_SUMMARY},
        {"quiet", no_argument, NULL, O_QUIET},
        {"help", no_argument, NULL, 'h'},
        {"max-samples", required_argument, NULL, O_MAXSAMPLES},
    };
    struct option options[sizeof own / sizeof own[0] + 32];
    srv_cli_merge_options(own, sizeof own / sizeof own[0], options, sizeof options / sizeof options[0]);
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        int engine = srv_cli_engine_option("serve", c, optarg, &o->engine);
        if (engine == 0)
            return 2;
        if (engine == 1)
            continue;
        bool ok = true;
        uint32_t value = 0;
        switch (c) {
        case O_BIND: o->net.bind = optarg; break;
        case O_PORT:
            ok = srv_cli_u32("serve", "--port", optarg, 0, 65535, &value);
            o->net.port = (int)value;
            break;
        case O_TOKEN: o->net.token = optarg; break;
        case O_FPS: ok = srv_cli_double("serve", "--fps", optarg, 0.001, 1000, &o->net.fps); break;
        case O_FRAMES: ok = srv_cli_u32("serve", "--frames", optarg, 1, 100000000, &o->net.frames); break;
        case O_MAXV:
            ok = srv_cli_u32("serve", "--max-viewers", optarg, 1, SRV_MAX_VIEWERS, &o->net.max_viewers);
            o->limits_set = true;
            break;
        case O_MAXRES:
            o->limits_set = true;
            ok = srv_cli_resolution("serve", "--max-res", optarg, PROTO_MAX_SIDE, &o->net.max_width,
                                    &o->net.max_height);
            break;
        case O_MAXMSG:
            ok = srv_cli_u32("serve", "--max-message", optarg, 1024, 16777216, &o->net.max_message);
            break;
        case O_RATE:
            ok = srv_cli_u32("serve", "--camera-rate", optarg, 1, 100000, &o->net.camera_rate);
            break;
        case O_MAXSAMPLES:
            ok = srv_cli_u32("serve", "--max-samples", optarg, 1, PROTO_MAX_SAMPLES, &o->net.max_samples);
            break;
        case O_RECORD: o->net.record_dir = srv_cli_dir_arg(optarg); break;
        case O_STATS: o->stats_path = optarg; break;
        case O_SUMMARY: o->summary_path = optarg; break;
        case O_QUIET: o->quiet = true; break;
        case 'h': {
            char names[256];
            srv_cli_effect_names(names, sizeof names);
            fputs(serve_usage, stdout);
            printf(srv_cli_engine_usage, names);
            printf(
                "  -h, --help           this text\n"
                "\n"
                "Exit status: 0 stopped by SIGINT, SIGTERM or --frames (the statistics, traces and summary\n"
                "written), 1 a failure (scene, port, writing files), 2 bad options or pools larger than the\n"
                "machine's memory; 128 + signal for a signal during the scene's load (nothing written).\n");
            return 0;
        }
        default: return srv_cli_getopt_error("serve", c, argv);
        }
        if (!ok)
            return 2;
    }
    if (!srv_cli_no_operands("serve", argc, argv))
        return 2;
    if (!o->net.token) {
        const char *env = getenv("FXCACHE_TOKEN");
        o->net.token = env && env[0] ? env : NULL;
    }
    if (o->net.token && (strlen(o->net.token) > PROTO_TOKEN_MAX || !o->net.token[0])) {
        fprintf(stderr, "fxcache serve: --token: 1..%d printable characters\n", PROTO_TOKEN_MAX);
        return 2;
    }
    for (const char *t = o->net.token; t && *t; t++)
        if (*t < 0x21 || *t > 0x7e) {
            fprintf(stderr, "fxcache serve: --token: only printable characters without spaces\n");
            return 2;
        }
    /* the address as it resolves ("127.example.com" need not be loopback), refused if it is not one the
     * server can listen on */
    char address[64], err[256];
    bool loopback = false;
    if (!srv_net_resolve_bind(o->net.bind, address, sizeof address, &loopback, err, sizeof err)) {
        fprintf(stderr, "fxcache serve: %s\n", err);
        return 2;
    }
    if (!loopback && !o->net.token) {
        fprintf(stderr,
                "fxcache serve: --bind %s is beyond loopback: give --token (or FXCACHE_TOKEN) so that only "
                "viewers with it can connect\n",
                o->net.bind);
        return 2;
    }
    return -1;
}

/* Memory at the limits, before anything is loaded: the pools, and every viewer at --max-res (the engine's
 * per-pixel buffers and the network's) with its sample viewer at --max-samples, within physical memory.
 * Limits given on the command line that cannot fit are refused with the figures (exit 2); the defaults
 * (16 viewers at 3840x2160, about 9 GiB) are lowered to the viewers that fit, with a warning line, so a
 * small machine still serves. False after the line of a refusal. */
static bool serve_memory_fits(serve_options *o)
{
    uint64_t physical = srv_cli_physical_memory();
    if (physical == 0)
        return true;
    srv_net_desc *d = &o->net;
    uint32_t viewers = d->max_viewers ? d->max_viewers : 16;
    uint64_t width = d->max_width ? d->max_width : 3840, height = d->max_height ? d->max_height : 2160;
    uint64_t samples = d->max_samples ? d->max_samples : 65536;
    uint64_t per_viewer = width * height * (SRV_VIEWER_BYTES_PER_PIXEL + SRV_NET_BYTES_PER_PIXEL) +
                          samples * (SRV_VIEWER_BYTES_PER_PIXEL + SRV_NET_BYTES_PER_SAMPLE);
    uint64_t pools = o->engine.no_cache ? 0 : (uint64_t)(o->engine.pool_mb * 1048576.0);
    uint32_t fit = srv_cli_viewers_that_fit(physical, pools, per_viewer, viewers);
    if (fit == viewers)
        return true;
    if (fit == 0 || o->limits_set) {
        fprintf(
            stderr,
            "fxcache serve: %u viewers at --max-res %llux%llu (and --max-samples %llu) need %.0f MiB with "
            "the block pools (%.0f MiB), more than this machine's %llu MiB of physical memory: lower "
            "--max-viewers, --max-res, --max-samples or --pool-mb\n",
            viewers, (unsigned long long)width, (unsigned long long)height, (unsigned long long)samples,
            ((double)pools + (double)per_viewer * viewers) / 1048576.0, pools / 1048576.0,
            (unsigned long long)(physical >> 20));
        return false;
    }
    fprintf(
        stderr,
        "fxcache serve: warning: %u viewers at %llux%llu would need %.0f MiB, more than this machine's %llu "
        "MiB of physical memory: at most %u viewers (--max-viewers %u)\n",
        viewers, (unsigned long long)width, (unsigned long long)height,
        ((double)pools + (double)per_viewer * viewers) / 1048576.0, (unsigned long long)(physical >> 20), fit,
        fit);
    d->max_viewers = fit;
    return true;
}

/* The network's totals, for the summary. */
static json_t *net_json(const serve_options *o, const srv_net *net, const srv_net_totals *t)
{
    json_t *refused = json_object();
    for (int code = 1; code < 32; code++)
        if (t->refused_by_code[code])
            json_object_set_new(refused, fxc_strerror(-code),
                                json_integer((json_int_t)t->refused_by_code[code]));
    json_t *j =
        json_pack("{s:s,s:i,s:f,s:i,s:I,s:I,s:I,s:o,s:I,s:I,s:I,s:I,s:f,s:I}", "bind", o->net.bind, "port",
                  srv_net_port(net), "fps", o->net.fps, "max_viewers", (int)o->net.max_viewers, "connections",
                  (json_int_t)t->connections, "viewers_joined", (json_int_t)t->viewers_joined, "refused",
                  (json_int_t)t->refused, "refused_by", refused, "frames_sent", (json_int_t)t->frames_sent,
                  "frames_dropped", (json_int_t)t->frames_dropped, "bytes_sent", (json_int_t)t->bytes_sent,
                  "cameras_received", (json_int_t)t->cameras_received, "encode_ms", t->encode_ms,
                  "buffer_bytes_peak", (json_int_t)t->buffer_bytes_peak);
    json_object_set_new(j, "sample_requests", json_integer((json_int_t)t->sample_requests));
    json_object_set_new(j, "sample_requests_dropped", json_integer((json_int_t)t->sample_requests_dropped));
    json_object_set_new(j, "samples_sent", json_integer((json_int_t)t->samples_sent));
    json_object_set_new(j, "samples_pixels", json_integer((json_int_t)t->samples_pixels));
    return j;
}

int srv_cmd_serve(int argc, char **argv)
{
    serve_options o = {.net = {.bind = "127.0.0.1", .port = 7681, .fps = 30}};
    srv_cli_engine_defaults(&o.engine);
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    if (!srv_cli_check_memory("serve", o.engine.no_cache ? 0 : o.engine.pool_mb, 0, 0, false) ||
        !serve_memory_fits(&o))
        return 2;
    if (o.net.record_dir && !srv_cli_make_dir("serve", o.net.record_dir))
        return 1;
    if ((o.stats_path && !srv_cli_output_file_ok("serve", "--stats", o.stats_path)) ||
        (o.summary_path && !srv_cli_output_file_ok("serve", "--summary", o.summary_path)) ||
        !srv_cli_output_files_differ("serve", "--stats", o.stats_path, "--summary", o.summary_path))
        return 1;
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    srv_cli_run run = {0};
    srv_cli_stats stats = {0};
    srv_net *net = NULL;
    int exit_code = srv_cli_run_open("serve", &o.engine, false, &run, &stop_requested);
    if (exit_code >= 0)
        goto done;
    exit_code = 1;
    if (o.stats_path && !srv_cli_stats_open(&stats, &run, o.stats_path))
        goto done;
    o.net.loop = run.loop;
    o.net.report = run.report;
    o.net.s = run.s;
    o.net.stop = &stop_requested;
    srv_loop_set_stop(run.loop, &stop_requested); /* a signal ends a long frame within a tile */
    o.net.progress = isatty(STDERR_FILENO);
    char err[512];
    if (srv_net_create(&o.net, &net, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache serve: %s\n", err);
        goto done;
    }
    printf("fxcache serve: listening on ws://%s:%d\n", srv_net_address(net), srv_net_port(net));
    fflush(stdout);
    fxc_result r = srv_net_run(net, err, sizeof err);
    if (r != FXC_OK)
        fprintf(stderr, "fxcache serve: %s\n", err);
    srv_cli_warn_exhausted(&run, &o.engine); /* degraded frames are never silent (sim says the same) */
    srv_net_totals totals;
    srv_net_get_totals(net, &totals);
    json_t *sum = srv_cli_summary_json(&run, &o.engine);
    json_object_set_new(sum, "interrupted", json_boolean(stop_requested));
    json_object_set_new(sum, "serve", net_json(&o, net, &totals));
    bool written = !o.summary_path || srv_cli_write_json("serve", o.summary_path, sum);
    json_decref(sum);
    if (!o.quiet) {
        srv_cli_print_summary(&run, o.engine.no_cache, false);
        printf("network:    %llu connections, %llu viewers joined, %llu refused; %llu frames sent (%.1f MB), "
               "%llu "
               "dropped for newer ones; %.2f ms encoding per frame sent\n",
               (unsigned long long)totals.connections, (unsigned long long)totals.viewers_joined,
               (unsigned long long)totals.refused, (unsigned long long)totals.frames_sent,
               totals.bytes_sent / 1e6, (unsigned long long)totals.frames_dropped,
               totals.frames_sent ? totals.encode_ms / (double)totals.frames_sent : 0.0);
        if (totals.sample_requests)
            printf("samples:    %llu sample requests, %llu answered (%llu pixels), %llu dropped for newer "
                   "ones\n",
                   (unsigned long long)totals.sample_requests, (unsigned long long)totals.samples_sent,
                   (unsigned long long)totals.samples_pixels,
                   (unsigned long long)totals.sample_requests_dropped);
    }
    exit_code = r == FXC_OK && written ? 0 : 1;
done:
    srv_net_free(net);
    if (!srv_cli_stats_close(&stats) && exit_code == 0)
        exit_code = 1;
    srv_cli_run_close(&run);
    return exit_code;
}

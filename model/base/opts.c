// model/base/opts.c — the command-line parser of every refl command (model/base/opts.h).
#include <math.h>
#include <stdarg.h>
#include <string.h>

#include "model/model.h"
#include "model/base/opts.h"

static void opt_lhs(const model_opt_t *o, char *buf, size_t n)
{
    snprintf(buf, n, "%s%s%s%s%s", o->name, o->alias ? ", " : "", o->alias ? o->alias : "", o->metavar ? " " : "",
             o->metavar ? o->metavar : "");
}

// The usage line: "usage: refl CMD SYNOPSIS [--opt V]..."
static void usage_line(const model_cli_t *c, FILE *f)
{
    fprintf(f, "usage: refl %s%s%s", c->cmd, c->synopsis && c->synopsis[0] ? " " : "", c->synopsis ? c->synopsis : "");
    for (int i = 0; i < c->nopts; i++) {
        const model_opt_t *o = &c->opts[i];
        fprintf(f, o->required ? " %s%s%s" : " [%s%s%s]", o->name, o->metavar ? " " : "", o->metavar ? o->metavar : "");
    }
    fprintf(f, "\n");
}

void model_cli_usage(const model_cli_t *c, FILE *f)
{
    usage_line(c, f);
    fprintf(f, "(refl %s --help for the options)\n", c->cmd);
}

// The one usage-error printer: "refl CMD: message", the usage line when the
// command's table is at hand, and the --help hint. Returns 2.
static int usage_error_v(const char *cmd, const model_cli_t *c, const char *fmt, va_list ap)
{
    fprintf(stderr, "refl %s: ", cmd);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    if (c) usage_line(c, stderr);
    fprintf(stderr, "(refl %s --help for the options)\n", cmd);
    return MODEL_CLI_USAGE;
}

int model_usage_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int rc = usage_error_v(cmd, NULL, fmt, ap);
    va_end(ap);
    return rc;
}

void model_cli_help(const model_cli_t *c, FILE *f)
{
    usage_line(c, f);
    if (c->about) fprintf(f, "\n%s\n", c->about);
    fprintf(f, "\noptions:\n");
    for (int i = 0; i < c->nopts; i++) {
        const model_opt_t *o = &c->opts[i];
        char lhs[96];
        opt_lhs(o, lhs, sizeof lhs);
        if (strlen(lhs) > 26) fprintf(f, "  %s\n  %-26s %s%s\n", lhs, "", o->help, o->required ? " (required)" : "");
        else fprintf(f, "  %-26s %s%s\n", lhs, o->help, o->required ? " (required)" : "");
    }
    fprintf(f, "  %-26s %s\n", "-h, --help", "print this help");
    if (c->epilog) fprintf(f, "\n%s\n", c->epilog);
    fprintf(f, "\n");
    model_cli_exit_status(f);
    fprintf(f, "\nrefl %s\n", REFL_VERSION);
}

void model_cli_exit_status(FILE *f)
{
    fprintf(f, "exit status (every refl command):\n"
               "  0  done\n"
               "  1  an error: the message names the file and line, device or option, and what to do\n"
               "  2  a usage error (an unknown option, a missing or bad value)\n"
               "  3  paused at an operator step or by Ctrl-C: run the same command again to continue\n"
               "  4  refl verify --fail-on-incorrect: the verdict is \"incorrect\"\n");
}

int model_cli_error(const model_cli_t *c, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int rc = usage_error_v(c->cmd, c, fmt, ap);
    va_end(ap);
    return rc;
}

static model_opt_t *find_opt(model_cli_t *c, const char *name, size_t len)
{
    for (int i = 0; i < c->nopts; i++) {
        model_opt_t *o = &c->opts[i];
        if ((strlen(o->name) == len && !strncmp(o->name, name, len)) ||
            (o->alias && strlen(o->alias) == len && !strncmp(o->alias, name, len)))
            return o;
    }
    return NULL;
}

model_opt_t *model_cli_opt(model_cli_t *c, const char *name) { return find_opt(c, name, strlen(name)); }

// The option with this old spelling (*which: its index among the option's
// old spellings), NULL when none has it.
static model_opt_t *find_old(model_cli_t *c, const char *name, size_t len, int *which)
{
    for (int i = 0; i < c->nopts; i++) {
        const char *p = c->opts[i].old;
        for (int k = 0; p && *p; k++) {
            while (*p == ' ') p++;
            size_t n = strcspn(p, " ");
            if (n && n == len && !strncmp(p, name, len)) {
                *which = k;
                return &c->opts[i];
            }
            p += n;
        }
    }
    return NULL;
}

// "--camera FILE: the option is --camera-model (the old spelling still
// works)", once a run for each old spelling.
static void note_old(model_opt_t *o, const char *spelled, size_t len, int which)
{
    unsigned bit = which < 32 ? 1u << which : 0;
    if (o->noted & bit) return;
    o->noted |= bit;
    const char *now = o->name[1] == '-' || !o->alias ? o->name : o->alias;
    model_note("%.*s%s%s: the option is %s (the old spelling still works)", (int)len, spelled,
               o->metavar ? " " : "", o->metavar ? o->metavar : "", now);
}

const char *model_cli_value(model_cli_t *c, const char *name)
{
    model_opt_t *o = find_opt(c, name, strlen(name));
    return o && o->given ? o->value : NULL;
}

int model_cli_double(model_cli_t *c, const char *name, double *out, double lo, bool lo_open, double hi,
                     const char *range_text)
{
    const char *s = model_cli_value(c, name);
    if (!s) return 0;
    double v;
    if (!model_parse_double(s, &v)) return model_cli_error(c, "option %s: '%s' is not a number", name, s);
    if ((lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi))
        return model_cli_error(c, "option %s: %s is out of range (%s)", name, s, range_text);
    *out = v;
    return 0;
}

int model_cli_long(model_cli_t *c, const char *name, long *out, long lo, long hi)
{
    const char *s = model_cli_value(c, name);
    if (!s) return 0;
    long v;
    if (!model_parse_int(s, &v)) return model_cli_error(c, "option %s: '%s' is not an integer", name, s);
    if (v < lo || v > hi) return model_cli_error(c, "option %s: %s is out of range (%ld..%ld)", name, s, lo, hi);
    *out = v;
    return 0;
}

int model_cli_channel(model_cli_t *c)
{
    const char *s = model_cli_value(c, "--channel");
    model_channel_t ch = MODEL_CHANNEL_LUMA;
    if (s && !model_channel_parse(s, &ch))
        return model_cli_error(c, "option --channel: '%s' is none of luma, r, g, b", s);
    model_image_set_channel(ch);
    return 0;
}

int model_cli_units(model_cli_t *c, double *unit_mm)
{
    const char *s = model_cli_value(c, "--units");
    if (s && !model_units_parse(s, unit_mm))
        return model_cli_error(c, "option --units: '%s' is none of mm, m, in", s);
    return 0;
}

// The value of a number option, checked against its range.
static int set_number(model_cli_t *c, model_opt_t *o, const char *v)
{
    if (o->kind == MODEL_OPT_KIND_INT) {
        long x;
        if (!model_parse_int(v, &x) || x < o->min || x > o->max)
            return model_cli_error(c, "%s needs a whole number from %.15g to %.15g, not '%s'", o->name, o->min, o->max,
                                   v);
        *(int *)o->dest = (int)x;
        return MODEL_CLI_OK;
    }
    double x;
    if (!model_parse_double(v, &x) || x < o->min || x > o->max) {
        if (isinf(o->max) && o->min == 0)
            return model_cli_error(c, "%s needs a number >= 0, not '%s'", o->name, v);
        if (isinf(o->max))
            return model_cli_error(c, "%s needs a number >= %.15g, not '%s'", o->name, o->min, v);
        return model_cli_error(c, "%s needs a number from %.15g to %.15g, not '%s'", o->name, o->min, o->max, v);
    }
    *(double *)o->dest = x;
    return MODEL_CLI_OK;
}

static bool is_number(const char *s)
{
    double v;
    return model_parse_double(s, &v);
}

// One more value of a list option.
static int list_add(model_cli_t *c, model_opt_t *o, const char *v)
{
    model_opt_list_t *l = o->dest;
    if (l->n >= l->cap) return model_cli_error(c, "%s: at most %d values", o->name, l->cap);
    l->v[l->n++] = v;
    return MODEL_CLI_OK;
}

static int take_option(model_cli_t *c, int argc, char **argv, int *i)
{
    const char *a = argv[*i];
    const char *eq = a[1] == '-' ? strchr(a, '=') : NULL;
    size_t len = eq ? (size_t)(eq - a) : strlen(a);
    model_opt_t *o = find_opt(c, a, len);
    int which = 0;
    if (!o && (o = find_old(c, a, len, &which))) note_old(o, a, len, which);
    if (!o) return model_cli_error(c, "unknown option '%.*s'", (int)len, a);
    if (o->given && !c->repeat_ok && o->kind != MODEL_OPT_KIND_LIST)
        return model_cli_error(c, "option %s given twice", o->name);
    o->given = true;
    if (o->kind == MODEL_OPT_KIND_FLAG) {
        if (eq) return model_cli_error(c, "option %s takes no value", o->name);
        o->value = "";
        if (o->dest) *(bool *)o->dest = true;
        return MODEL_CLI_OK;
    }
    const char *v;
    if (eq) {
        v = eq + 1;
    } else {
        if (*i + 1 >= argc) return model_cli_error(c, "option %s needs a value (%s)", o->name, o->metavar);
        v = argv[++*i];
    }
    if (!v[0]) return model_cli_error(c, "option %s: empty value", o->name);
    o->value = v;
    if (o->kind == MODEL_OPT_KIND_LIST) {
        int rc = list_add(c, o, v);
        // greedy: the arguments after it up to the next option ("-" alone is a value)
        while (rc == MODEL_CLI_OK && o->min > 0 && !eq && *i + 1 < argc &&
               !(argv[*i + 1][0] == '-' && argv[*i + 1][1]))
            rc = list_add(c, o, argv[++*i]);
        return rc;
    }
    if (o->kind == MODEL_OPT_KIND_STRING) {
        if (o->dest) *(const char **)o->dest = v;
        return MODEL_CLI_OK;
    }
    return set_number(c, o, v);
}

int model_cli_parse(model_cli_t *c, int argc, char **argv)
{
    bool only_positional = false;
    c->npositional = 0;
    for (int i = 0; i < c->nopts; i++) {
        c->opts[i].given = false;
        c->opts[i].value = NULL;
        c->opts[i].noted = 0;
        if (c->opts[i].kind == MODEL_OPT_KIND_LIST) ((model_opt_list_t *)c->opts[i].dest)->n = 0;
    }
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!only_positional && (!strcmp(a, "--help") || !strcmp(a, "-h"))) {
            model_cli_help(c, stdout);
            return MODEL_CLI_HELP;
        }
        if (!only_positional && !strcmp(a, "--")) {
            only_positional = true;
            continue;
        }
        if (!only_positional && a[0] == '-' && a[1] != 0 && !(c->numbers_positional && is_number(a))) {
            int rc = take_option(c, argc, argv, &i);
            if (rc != MODEL_CLI_OK) return rc;
            continue;
        }
        if (c->npositional >= c->max_positional || c->npositional >= MODEL_CLI_POSITIONAL_MAX) {
            if (c->max_positional == 1 && c->synopsis && c->synopsis[0]) return model_cli_error(c, "unexpected argument '%s' (one %s only)", a, c->synopsis);
            return model_cli_error(c, "unexpected argument '%s'", a);
        }
        c->positional[c->npositional++] = a;
    }
    if (c->npositional < c->min_positional)
        return model_cli_error(c, "missing %s", c->synopsis ? c->synopsis : "arguments");
    for (int i = 0; i < c->nopts; i++)
        if (c->opts[i].required && !c->opts[i].given)
            return model_cli_error(c, "missing required option %s %s", c->opts[i].name,
                                   c->opts[i].metavar ? c->opts[i].metavar : "");
    return MODEL_CLI_OK;
}

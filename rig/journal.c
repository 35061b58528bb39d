// rig/journal.c — the session journal: DIR/session.sqlite (see rig/rig.h,
// "Capture sessions"). WAL mode, synchronous = FULL, one transaction per frame;
// a schema_version table; calls are serialised by a mutex (the capture's main
// thread logs events while the writer thread commits frames).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <pthread.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "model/model.h"
#include "rig/rig.h"

#define SCHEMA_VERSION 1

struct rig_journal {
    sqlite3        *db;
    char           *path;
    pthread_mutex_t lock;
};

static const char schema[] =
    "CREATE TABLE schema_version(version INTEGER NOT NULL);"
    "CREATE TABLE session(id INTEGER PRIMARY KEY CHECK(id = 1), created_utc TEXT, state TEXT NOT NULL,"
    " plan_path TEXT, plan_text TEXT, plan_sha256 TEXT, rig_path TEXT, rig_text TEXT, rig_sha256 TEXT,"
    " sample TEXT, sample_kind TEXT, operator TEXT, notes TEXT, refl_version TEXT, facts_json TEXT,"
    " nsteps INTEGER);"
    "CREATE TABLE steps(idx INTEGER PRIMARY KEY, kind TEXT NOT NULL, angle_index INTEGER, lamp_set INTEGER,"
    " exposure_index INTEGER, repeat INTEGER, grp INTEGER, angle_deg REAL, lamps TEXT, exposure_us REAL,"
    " gain REAL, status TEXT NOT NULL DEFAULT 'pending', note TEXT);"
    "CREATE TABLE frames(step INTEGER PRIMARY KEY REFERENCES steps(idx), file TEXT UNIQUE NOT NULL,"
    " sha256 TEXT NOT NULL, t_trigger_utc TEXT, t_written_utc TEXT, t_trigger_s REAL, t_written_s REAL,"
    " commanded_deg REAL, measured_deg REAL, lamps TEXT, exposure_us REAL, gain REAL, mean REAL, max REAL,"
    " roi_max REAL, saturated_fraction REAL, width INTEGER, height INTEGER, pixel_format TEXT,"
    " frame_id INTEGER);"
    "CREATE TABLE events(id INTEGER PRIMARY KEY, t_utc TEXT, step INTEGER, kind TEXT, message TEXT);";

static int jfail(rig_journal_t *j, const char *what)
{
    int code = j && j->db ? sqlite3_extended_errcode(j->db) : SQLITE_ERROR;
    bool full = (code & 0xff) == SQLITE_FULL;
    return rig_fail(full ? RIG_ERR_IO : RIG_ERR_IO, "journal %s: %s: %s%s", j && j->path ? j->path : "?", what,
                    j && j->db ? sqlite3_errmsg(j->db) : "out of memory",
                    full ? " (disk full: free space, then refl capture --resume)" : "");
}

static int open_db(rig_journal_t **out, const char *dir, bool create)
{
    *out = NULL;
    rig_journal_t *j = calloc(1, sizeof *j);
    if (!j) return rig_fail(RIG_ERR_NO_MEM, "journal: out of memory");
    pthread_mutex_init(&j->lock, NULL);
    j->path = g_strdup_printf("%s/session.sqlite", dir);
    struct stat st;
    bool exists = stat(j->path, &st) == 0;
    int rc = 0;
    if (create && exists) {
        rc = rig_fail(RIG_ERR_INVALID, "%s already holds a session: continue it with refl capture --resume %s, or "
                      "choose another -o DIR", dir, dir);
        goto fail;
    }
    if (!create && !exists) {
        rc = rig_fail(RIG_ERR_NO_DEVICE, "%s: no session here (no session.sqlite)", dir);
        goto fail;
    }
    if (sqlite3_open_v2(j->path, &j->db, SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) |
                        SQLITE_OPEN_FULLMUTEX, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot open");
        goto fail;
    }
    sqlite3_busy_timeout(j->db, 10000);
    if (sqlite3_exec(j->db, "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL; PRAGMA foreign_keys=ON;", NULL,
                     NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot set WAL mode");
        goto fail;
    }
    if (!create) {
        sqlite3_stmt *s = NULL;
        int v = -1;
        if (sqlite3_prepare_v2(j->db, "SELECT version FROM schema_version", -1, &s, NULL) == SQLITE_OK &&
            sqlite3_step(s) == SQLITE_ROW)
            v = sqlite3_column_int(s, 0);
        sqlite3_finalize(s);
        if (v != SCHEMA_VERSION) {
            rc = rig_fail(RIG_ERR_PROTOCOL, "journal %s: schema version %d, this refl reads version %d", j->path, v,
                          SCHEMA_VERSION);
            goto fail;
        }
    }
    *out = j;
    return 0;
fail:
    rig_journal_close(j);
    return rc;
}

int rig_journal_open(rig_journal_t **out, const char *dir) { return open_db(out, dir, false); }

void rig_journal_close(rig_journal_t *j)
{
    if (!j) return;
    if (j->db) sqlite3_close(j->db);
    pthread_mutex_destroy(&j->lock);
    g_free(j->path);
    free(j);
}

int rig_journal_create(rig_journal_t **out, const char *dir, const rig_plan_t *p, const char *rig_path,
                       const char *rig_text, const char *rig_sha256, const char *session_json)
{
    rig_journal_t *j = NULL;
    int rc = open_db(&j, dir, true);
    if (rc) return rc;
    sqlite3_stmt *s = NULL;
    char now[40];
    model_utc_text(model_realtime_s(), now);
    if (sqlite3_exec(j->db, "BEGIN", NULL, NULL, NULL) != SQLITE_OK ||
        sqlite3_exec(j->db, schema, NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot create the tables");
        goto fail;
    }
    char ver[64];
    snprintf(ver, sizeof ver, "INSERT INTO schema_version VALUES(%d)", SCHEMA_VERSION);
    if (sqlite3_exec(j->db, ver, NULL, NULL, NULL) != SQLITE_OK ||
        sqlite3_prepare_v2(j->db, "INSERT INTO session VALUES(1,?,'running',?,?,?,?,?,?,?,?,?,?,?,?,?)", -1, &s,
                           NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot write the session");
        goto fail;
    }
    const char *txt[] = { now, p->path, p->text, p->sha256, rig_path, rig_text, rig_sha256, p->sample,
                          p->sample_kind, p->operator_name, p->notes, REFL_VERSION, session_json };
    for (int i = 0; i < 13; i++) sqlite3_bind_text(s, i + 1, txt[i], -1, SQLITE_TRANSIENT);
    sqlite3_bind_int(s, 14, p->nsteps);
    if (sqlite3_step(s) != SQLITE_DONE) {
        rc = jfail(j, "cannot write the session");
        goto fail;
    }
    sqlite3_finalize(s);
    s = NULL;
    if (sqlite3_prepare_v2(j->db, "INSERT INTO steps(idx,kind,angle_index,lamp_set,exposure_index,repeat,grp,"
                           "angle_deg,lamps,exposure_us,gain) VALUES(?,?,?,?,?,?,?,?,?,?,?)", -1, &s, NULL) !=
        SQLITE_OK) {
        rc = jfail(j, "cannot write the steps");
        goto fail;
    }
    for (int i = 0; i < p->nsteps; i++) {
        const rig_step_t *st = &p->steps[i];
        sqlite3_reset(s);
        sqlite3_bind_int(s, 1, st->index);
        sqlite3_bind_text(s, 2, st->kind == RIG_STEP_DARK ? "dark" : "light", -1, SQLITE_STATIC);
        sqlite3_bind_int(s, 3, st->angle_index);
        sqlite3_bind_int(s, 4, st->lamp_set);
        sqlite3_bind_int(s, 5, st->exposure_index);
        sqlite3_bind_int(s, 6, st->repeat);
        sqlite3_bind_int(s, 7, st->group);
        sqlite3_bind_double(s, 8, st->angle_deg);
        sqlite3_bind_text(s, 9, st->lamps, -1, SQLITE_TRANSIENT);
        sqlite3_bind_double(s, 10, st->exposure_us);
        sqlite3_bind_double(s, 11, st->gain);
        if (sqlite3_step(s) != SQLITE_DONE) {
            rc = jfail(j, "cannot write the steps");
            goto fail;
        }
    }
    sqlite3_finalize(s);
    s = NULL;
    if (sqlite3_exec(j->db, "COMMIT", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot commit the session");
        goto fail;
    }
    *out = j;
    return 0;
fail:
    sqlite3_finalize(s);
    rig_journal_close(j);
    return rc ? rc : RIG_ERR_IO;
}

static char *col_text(sqlite3_stmt *s, int i)
{
    const unsigned char *t = sqlite3_column_text(s, i);
    return strdup(t ? (const char *)t : "");
}

int rig_journal_source(rig_journal_t *j, const char *which, char **path, char **text, char **sha256)
{
    char sql[128];
    bool plan = !strcmp(which, "plan");
    snprintf(sql, sizeof sql, "SELECT %s FROM session", plan ? "plan_path, plan_text, plan_sha256"
                                                             : "rig_path, rig_text, rig_sha256");
    sqlite3_stmt *s = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) != SQLITE_OK || sqlite3_step(s) != SQLITE_ROW) {
        rc = jfail(j, "cannot read the session");
    } else {
        if (path) *path = col_text(s, 0);
        if (text) *text = col_text(s, 1);
        if (sha256) *sha256 = col_text(s, 2);
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

int rig_journal_facts(rig_journal_t *j, char **json)
{
    sqlite3_stmt *s = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT facts_json FROM session", -1, &s, NULL) != SQLITE_OK ||
        sqlite3_step(s) != SQLITE_ROW)
        rc = jfail(j, "cannot read the session");
    else
        *json = col_text(s, 0);
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

int rig_journal_nsteps(rig_journal_t *j)
{
    sqlite3_stmt *s = NULL;
    int n = -1;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT count(*) FROM steps", -1, &s, NULL) == SQLITE_OK &&
        sqlite3_step(s) == SQLITE_ROW)
        n = sqlite3_column_int(s, 0);
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return n;
}

int rig_journal_steps(rig_journal_t *j, rig_step_t **steps, char **status, int *n)
{
    *steps = NULL;
    *status = NULL;
    *n = 0;
    int total = rig_journal_nsteps(j);
    if (total < 0) return jfail(j, "cannot read the steps");
    rig_step_t *st = calloc((size_t)total + 1, sizeof *st);
    char *stat = calloc((size_t)total + 1, 1);
    sqlite3_stmt *s = NULL;
    int rc = 0, k = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT idx,kind,angle_index,lamp_set,exposure_index,repeat,grp,angle_deg,lamps,"
                           "exposure_us,gain,status FROM steps ORDER BY idx", -1, &s, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot read the steps");
    } else {
        while (k < total && sqlite3_step(s) == SQLITE_ROW) {
            rig_step_t *t = &st[k];
            t->index = sqlite3_column_int(s, 0);
            t->kind = !strcmp((const char *)sqlite3_column_text(s, 1), "dark") ? RIG_STEP_DARK : RIG_STEP_LIGHT;
            t->angle_index = sqlite3_column_int(s, 2);
            t->lamp_set = sqlite3_column_int(s, 3);
            t->exposure_index = sqlite3_column_int(s, 4);
            t->repeat = sqlite3_column_int(s, 5);
            t->group = sqlite3_column_int(s, 6);
            t->angle_deg = sqlite3_column_double(s, 7);
            const unsigned char *l = sqlite3_column_text(s, 8);
            snprintf(t->lamps, sizeof t->lamps, "%s", l ? (const char *)l : "none");
            t->exposure_us = sqlite3_column_double(s, 9);
            t->gain = sqlite3_column_double(s, 10);
            const unsigned char *x = sqlite3_column_text(s, 11);
            stat[k] = x ? (char)x[0] : 'p';
            k++;
        }
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    if (rc) {
        free(st);
        free(stat);
        return rc;
    }
    *steps = st;
    *status = stat;
    *n = k;
    return 0;
}

int rig_journal_frames(rig_journal_t *j, rig_frame_row_t **rows, int *n)
{
    *rows = NULL;
    *n = 0;
    int total = rig_journal_nsteps(j);
    if (total < 0) return jfail(j, "cannot read the frames");
    rig_frame_row_t *r = calloc((size_t)total + 1, sizeof *r);
    sqlite3_stmt *s = NULL;
    int rc = 0, k = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT step,file,sha256,t_trigger_s,t_written_s,commanded_deg,measured_deg,"
                           "lamps,exposure_us,gain,mean,max,roi_max,saturated_fraction,width,height,pixel_format,"
                           "frame_id FROM frames ORDER BY step", -1, &s, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot read the frames");
    } else {
        while (k < total && sqlite3_step(s) == SQLITE_ROW) {
            rig_frame_row_t *f = &r[k++];
            f->step = sqlite3_column_int(s, 0);
            snprintf(f->file, sizeof f->file, "%s", (const char *)sqlite3_column_text(s, 1));
            snprintf(f->sha256, sizeof f->sha256, "%s", (const char *)sqlite3_column_text(s, 2));
            f->t_trigger_utc_s = sqlite3_column_double(s, 3);
            f->t_written_utc_s = sqlite3_column_double(s, 4);
            f->commanded_deg = sqlite3_column_double(s, 5);
            f->measured_deg = sqlite3_column_double(s, 6);
            const unsigned char *l = sqlite3_column_text(s, 7);
            snprintf(f->lamps, sizeof f->lamps, "%s", l ? (const char *)l : "");
            f->exposure_us = sqlite3_column_double(s, 8);
            f->gain = sqlite3_column_double(s, 9);
            f->mean = sqlite3_column_double(s, 10);
            f->max = sqlite3_column_double(s, 11);
            f->roi_max = sqlite3_column_double(s, 12);
            f->saturated_fraction = sqlite3_column_double(s, 13);
            f->width = sqlite3_column_int(s, 14);
            f->height = sqlite3_column_int(s, 15);
            const unsigned char *pf = sqlite3_column_text(s, 16);
            snprintf(f->pixel_format, sizeof f->pixel_format, "%s", pf ? (const char *)pf : "");
            f->frame_id = (uint64_t)sqlite3_column_int64(s, 17);
        }
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    if (rc) {
        free(r);
        return rc;
    }
    *rows = r;
    *n = k;
    return 0;
}

int rig_journal_frame_done(rig_journal_t *j, const rig_frame_row_t *f)
{
    sqlite3_stmt *s = NULL, *u = NULL;
    int rc = 0;
    char t0[40], t1[40];
    model_utc_text(f->t_trigger_utc_s, t0);
    model_utc_text(f->t_written_utc_s, t1);
    pthread_mutex_lock(&j->lock);
    if (sqlite3_exec(j->db, "BEGIN IMMEDIATE", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot begin a frame transaction");
        goto done;
    }
    if (sqlite3_prepare_v2(j->db, "INSERT INTO frames VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)", -1, &s,
                           NULL) != SQLITE_OK ||
        sqlite3_prepare_v2(j->db, "UPDATE steps SET status='done' WHERE idx=? AND status='pending'", -1, &u,
                           NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot record a frame");
        goto rollback;
    }
    sqlite3_bind_int(s, 1, f->step);
    sqlite3_bind_text(s, 2, f->file, -1, SQLITE_STATIC);
    sqlite3_bind_text(s, 3, f->sha256, -1, SQLITE_STATIC);
    sqlite3_bind_text(s, 4, t0, -1, SQLITE_STATIC);
    sqlite3_bind_text(s, 5, t1, -1, SQLITE_STATIC);
    sqlite3_bind_double(s, 6, f->t_trigger_utc_s);
    sqlite3_bind_double(s, 7, f->t_written_utc_s);
    sqlite3_bind_double(s, 8, f->commanded_deg);
    sqlite3_bind_double(s, 9, f->measured_deg);
    sqlite3_bind_text(s, 10, f->lamps, -1, SQLITE_STATIC);
    sqlite3_bind_double(s, 11, f->exposure_us);
    sqlite3_bind_double(s, 12, f->gain);
    sqlite3_bind_double(s, 13, f->mean);
    sqlite3_bind_double(s, 14, f->max);
    sqlite3_bind_double(s, 15, f->roi_max);
    sqlite3_bind_double(s, 16, f->saturated_fraction);
    sqlite3_bind_int(s, 17, f->width);
    sqlite3_bind_int(s, 18, f->height);
    sqlite3_bind_text(s, 19, f->pixel_format, -1, SQLITE_STATIC);
    sqlite3_bind_int64(s, 20, (sqlite3_int64)f->frame_id);
    sqlite3_bind_int(u, 1, f->step);
    if (sqlite3_step(s) != SQLITE_DONE || sqlite3_step(u) != SQLITE_DONE || sqlite3_changes(j->db) != 1) {
        rc = jfail(j, "cannot record a frame (a step recorded twice?)");
        goto rollback;
    }
    if (sqlite3_exec(j->db, "COMMIT", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot commit a frame");
        goto rollback;
    }
    goto done;
rollback:
    sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
done:
    sqlite3_finalize(s);
    sqlite3_finalize(u);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

static int exec_bind(rig_journal_t *j, const char *sql, int nint, const int *ints, int ntext, const char **texts)
{
    sqlite3_stmt *s = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot write");
    } else {
        for (int i = 0; i < ntext; i++) sqlite3_bind_text(s, i + 1, texts[i], -1, SQLITE_TRANSIENT);
        for (int i = 0; i < nint; i++) sqlite3_bind_int(s, ntext + i + 1, ints[i]);
        if (sqlite3_step(s) != SQLITE_DONE) rc = jfail(j, "cannot write");
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

int rig_journal_step_skipped(rig_journal_t *j, int step, const char *why)
{
    return exec_bind(j, "UPDATE steps SET status='skipped', note=? WHERE idx=? AND status='pending'", 1, &step, 1,
                     &why);
}

int rig_journal_event(rig_journal_t *j, int step, const char *kind, const char *fmt, ...)
{
    if (!j) return 0;
    va_list ap;
    va_start(ap, fmt);
    char *msg = g_strdup_vprintf(fmt, ap);
    va_end(ap);
    char now[40];
    model_utc_text(model_realtime_s(), now);
    const char *t[] = { now, kind, msg };
    int rc = exec_bind(j, "INSERT INTO events(t_utc, kind, message, step) VALUES(?,?,?,?)", 1, &step, 3, t);
    g_free(msg);
    return rc;
}

int rig_journal_set_state(rig_journal_t *j, const char *state)
{
    return exec_bind(j, "UPDATE session SET state=?", 0, NULL, 1, &state);
}

int rig_journal_state(rig_journal_t *j, char *out, size_t size)
{
    sqlite3_stmt *s = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT state FROM session", -1, &s, NULL) != SQLITE_OK ||
        sqlite3_step(s) != SQLITE_ROW)
        rc = jfail(j, "cannot read the session state");
    else
        snprintf(out, size, "%s", (const char *)sqlite3_column_text(s, 0));
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

// rig/session/journal.c — the session journal: DIR/session.sqlite (see
// rig/session/session.h, "Capture sessions"). WAL mode, synchronous = FULL, one
// transaction per frame; calls are serialised by a mutex (the capture's main
// thread logs events while the writer thread commits frames).
//
// The schema's version is the one row of table schema_version:
//   1  frames keyed by step (a session of one camera), without the camera
//      column; the columns gain_unit, black_level, gamma, temperature_c,
//      firmware and camera_settings may be missing.
//   2  frames keyed by (step, camera), with the camera column (the rig file's
//      name of the camera) and every column of RIG_FRAME_COLUMNS. Written
//      by this refl.
// The reader reads versions 1 and 2 as they are (a version-1 journal's frames
// read as camera "camera"); the writer continuing a version-1 journal
// (rig_journal_resume) migrates it to 2 first (one transaction). A frame
// column a journal lacks reads as NULL ("" or 0), and writing a frame adds it.
// A journal of a higher version, or without one, is refused naming both.
//
// Readers (rig_journal_open) never write the journal: no WAL switch, no
// migration, no checkpoint.
// - A WAL beside the journal holds commits (a writer is at work, or died
//   before its last checkpoint), or the journal and its directory can be
//   written (a writer may come): SQLite's read-only open, which shares the
//   writer's locks and reads its WAL through the -shm index (SQLite creates
//   an empty -wal and the -shm where they are missing and may leave them).
// - Neither (another user's session, a read-only archive, a journal without
//   write permission): immutable (file:...?immutable=1: no lock, no file
//   made; SQLite would read past a WAL, which is why only then).
// - A WAL with commits that SQLite cannot read in place (the directory cannot
//   be written and no -shm is there): the journal and its WAL are copied into
//   a private temporary directory and read there, so no committed frame is
//   lost; the copy is removed at close.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <jansson.h>
#include <math.h>
#include <pthread.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "model/base/report.h"
#include "rig/rig.h"

#define SCHEMA_VERSION 2   // the version written; versions 1 to SCHEMA_VERSION are read

struct rig_journal {
    sqlite3        *db;
    char           *path;
    char           *copy_dir;           // a reader's private copy of the journal and its WAL, removed at close
    pthread_mutex_t lock;
    bool            frame_columns_ok;   // the frames table has every column (add_frame_columns)
};

static const char schema[] =
    "CREATE TABLE schema_version(version INTEGER NOT NULL);"
    "CREATE TABLE session(id INTEGER PRIMARY KEY CHECK(id = 1), created_utc TEXT, state TEXT NOT NULL,"
    " plan_path TEXT, plan_text TEXT, plan_sha256 TEXT, rig_path TEXT, rig_text TEXT, rig_sha256 TEXT,"
    " sample TEXT, sample_kind TEXT, operator TEXT, notes TEXT, refl_version TEXT, facts_json TEXT,"
    " nsteps INTEGER);"
    "CREATE TABLE steps(idx INTEGER PRIMARY KEY, kind TEXT NOT NULL, angle_index INTEGER, lamp_set INTEGER,"
    " exposure_index INTEGER, repeat INTEGER, grp INTEGER, angle_deg REAL, lamps TEXT, exposure_us REAL,"
    " gain REAL, status TEXT NOT NULL DEFAULT 'pending', note TEXT);";
// then the frames table (frames_sql, from RIG_FRAME_COLUMNS), then:
static const char schema_events[] =
    "CREATE TABLE events(id INTEGER PRIMARY KEY, t_utc TEXT, step INTEGER, kind TEXT, message TEXT);";

// ---------------------------------------------------------------------------
// The frames table's SQL, from RIG_FRAME_COLUMNS (rig/session/session.h)

#define IS_UTC_INT  0
#define IS_UTC_REAL 0
#define IS_UTC_TEXT 0
#define IS_UTC_U64  0
#define IS_UTC_UTC  1

static const struct {
    const char *column, *decl;
    bool        utc;            // a column only (not read back)
} frame_columns[] = {
#define FRAME_COLUMN_(kind, name, column, decl, csv, size) { column, decl, IS_UTC_##kind },
    RIG_FRAME_COLUMNS(FRAME_COLUMN_)
#undef FRAME_COLUMN_
};
#define NFRAME_COLUMNS ((int)(sizeof frame_columns / sizeof frame_columns[0]))

typedef enum { FRAMES_CREATE, FRAMES_INSERT, FRAMES_SELECT } frames_sql_t;

// Does the journal's frames table have this column? (A version-1 journal may
// lack gain_unit .. camera_settings.)
static bool frames_has_column(sqlite3 *db, const char *column)
{
    sqlite3_stmt *s = NULL;
    bool has = true;   // when the question cannot be asked, the SELECT says what is wrong
    if (sqlite3_prepare_v2(db, "SELECT count(*) FROM pragma_table_info('frames') WHERE name=?", -1, &s, NULL) ==
        SQLITE_OK) {
        sqlite3_bind_text(s, 1, column, -1, SQLITE_STATIC);
        if (sqlite3_step(s) == SQLITE_ROW) has = sqlite3_column_int(s, 0) > 0;
    }
    sqlite3_finalize(s);
    return has;
}

// "CREATE TABLE frames(...);", "INSERT INTO frames VALUES(?,...)" or
// "SELECT ... FROM frames ORDER BY step" (the columns rig_frame_row_t holds;
// with db, a column the journal lacks reads as NULL: "" or 0, and camera as
// "camera").
// Caller g_free()s.
static char *frames_sql(frames_sql_t what, sqlite3 *db)
{
    GString *q = g_string_new(what == FRAMES_CREATE   ? "CREATE TABLE frames("
                              : what == FRAMES_INSERT ? "INSERT INTO frames("
                                                      : "SELECT ");
    if (what == FRAMES_INSERT) {   // by name: a journal with added columns has them in another order
        for (int i = 0; i < NFRAME_COLUMNS; i++)
            g_string_append_printf(q, "%s%s", i ? "," : "", frame_columns[i].column);
        g_string_append(q, ") VALUES(");
    }
    int k = 0;
    for (int i = 0; i < NFRAME_COLUMNS; i++) {
        if (what == FRAMES_SELECT && frame_columns[i].utc) continue;
        if (k++) g_string_append(q, what == FRAMES_CREATE ? ", " : ",");
        if (what == FRAMES_CREATE) g_string_append_printf(q, "%s %s", frame_columns[i].column, frame_columns[i].decl);
        else if (what == FRAMES_INSERT) g_string_append(q, "?");
        else if (db && !frames_has_column(db, frame_columns[i].column))   // a version-1 journal's one camera
            g_string_append(q, strcmp(frame_columns[i].column, "camera") ? "NULL" : "'camera'");
        else g_string_append(q, frame_columns[i].column);
    }
    g_string_append(q, what == FRAMES_CREATE   ? ", PRIMARY KEY(step, camera));"
                       : what == FRAMES_INSERT ? ")"
                                               : " FROM frames ORDER BY step, rowid");
    return g_string_free(q, FALSE);
}

// Bind row f to the INSERT of frames_sql; read the SELECT's row into f.
static void frame_bind(sqlite3_stmt *s, const rig_frame_row_t *f)
{
    int k = 1;
#define BIND_INT(name)  sqlite3_bind_int(s, k++, f->name);
#define BIND_REAL(name) sqlite3_bind_double(s, k++, f->name);
#define BIND_TEXT(name) sqlite3_bind_text(s, k++, f->name, -1, SQLITE_STATIC);
#define BIND_U64(name)  sqlite3_bind_int64(s, k++, (sqlite3_int64)f->name);
#define BIND_UTC(name)                                           \
    {                                                            \
        char t_[40];                                             \
        model_utc_text(f->name, t_);                             \
        sqlite3_bind_text(s, k++, t_, -1, SQLITE_TRANSIENT);     \
    }
#define BIND_(kind, name, column, decl, csv, size) BIND_##kind(name)
    RIG_FRAME_COLUMNS(BIND_)
#undef BIND_
}

static void frame_read(sqlite3_stmt *s, rig_frame_row_t *f)
{
    int k = 0;
#define READ_INT(name)  f->name = sqlite3_column_int(s, k++);
#define READ_REAL(name) f->name = sqlite3_column_double(s, k++);
#define READ_TEXT(name)                                                               \
    {                                                                                 \
        const unsigned char *t_ = sqlite3_column_text(s, k++);                        \
        snprintf(f->name, sizeof f->name, "%s", t_ ? (const char *)t_ : "");          \
    }
#define READ_U64(name)  f->name = (uint64_t)sqlite3_column_int64(s, k++);
#define READ_UTC(name)
#define READ_(kind, name, column, decl, csv, size) READ_##kind(name)
    RIG_FRAME_COLUMNS(READ_)
#undef READ_
}

static int jfail(rig_journal_t *j, const char *what)
{
    int code = j && j->db ? sqlite3_extended_errcode(j->db) & 0xff : SQLITE_ERROR;
    const char *path = j && j->path ? j->path : "?";
    if (code == SQLITE_CORRUPT || code == SQLITE_NOTADB)
        return rig_fail(RIG_ERR_IO, "journal %s: %s: %s (the journal is damaged: sqlite3 %s .recover > recovered.sql "
                        "saves what can be read)", path, what, sqlite3_errmsg(j->db), path);
    return rig_fail(RIG_ERR_IO, "journal %s: %s: %s%s", path, what, j && j->db ? sqlite3_errmsg(j->db) : "out of memory",
                    code == SQLITE_FULL ? " (disk full: free space, then refl capture --resume)" : "");
}

// Schema 1 -> 2 in one transaction: the frames table gets its camera column
// (every frame "camera", the one camera of a version-1 session) and the key
// (step, camera).
static int migrate_v1(rig_journal_t *j)
{
    GString *cols = g_string_new("");
    for (int i = 0; i < NFRAME_COLUMNS; i++)   // the columns it has (a version-1 journal may lack some)
        if (strcmp(frame_columns[i].column, "camera") && frames_has_column(j->db, frame_columns[i].column))
            g_string_append_printf(cols, "%s%s", cols->len ? "," : "", frame_columns[i].column);
    char *create = frames_sql(FRAMES_CREATE, NULL);
    char *sql = g_strdup_printf("BEGIN IMMEDIATE; ALTER TABLE frames RENAME TO frames_v1; %s "
                                "INSERT INTO frames(%s) SELECT %s FROM frames_v1; DROP TABLE frames_v1; "
                                "UPDATE schema_version SET version = %d; COMMIT;",
                                create, cols->str, cols->str, SCHEMA_VERSION);
    int rc = 0;
    if (sqlite3_exec(j->db, sql, NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot migrate the journal from schema version 1 (one camera) to 2");
        sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
    }
    g_free(sql);
    g_free(create);
    g_string_free(cols, TRUE);
    return rc;
}

typedef enum { JOURNAL_READ, JOURNAL_CREATE, JOURNAL_RESUME } journal_open_t;

// SQLite's URI of path opened immutable: every byte but unreserved ones and
// '/' percent-encoded ("file:///abs/path" or "file:rel/path").
static char *immutable_uri(const char *path)
{
    GString *u = g_string_new(path[0] == '/' ? "file://" : "file:");
    for (const unsigned char *c = (const unsigned char *)path; *c; c++) {
        if (g_ascii_isalnum(*c) || strchr("/-._~", *c)) g_string_append_c(u, (char)*c);
        else g_string_append_printf(u, "%%%02X", *c);
    }
    g_string_append(u, "?immutable=1");
    return g_string_free(u, FALSE);
}

static bool copy_file(const char *from, const char *to)
{
    FILE *in = fopen(from, "rb"), *out = in ? fopen(to, "wb") : NULL;
    bool ok = in && out;
    char buf[65536];
    for (size_t n; ok && (n = fread(buf, 1, sizeof buf, in)) > 0;) ok = fwrite(buf, 1, n, out) == n;
    ok = ok && !ferror(in);
    if (out && fclose(out) != 0) ok = false;
    if (in) fclose(in);
    return ok;
}

static void remove_copy(rig_journal_t *j)
{
    if (!j->copy_dir) return;
    static const char *const names[] = { "session.sqlite", "session.sqlite-wal", "session.sqlite-shm" };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        char *p = g_build_filename(j->copy_dir, names[i], NULL);
        unlink(p);
        g_free(p);
    }
    rmdir(j->copy_dir);
    g_free(j->copy_dir);
    j->copy_dir = NULL;
}

// The journal and the WAL beside it copied into a private temporary directory
// and opened there (SQLite rebuilds the WAL index from the WAL): a WAL that
// holds commits the journal lacks, where SQLite cannot read it in place.
static int open_copy(rig_journal_t *j, const char *wal)
{
    GError *err = NULL;
    if (!(j->copy_dir = g_dir_make_tmp("refl-journal-XXXXXX", &err))) {
        int rc = rig_fail(RIG_ERR_IO, "journal %s: its WAL %s holds commits the journal lacks (its writer did not "
                          "close it), SQLite cannot read them where the directory cannot be written, and no private "
                          "copy can be made: %s; copy the session directory to a writable place", j->path, wal,
                          err ? err->message : "?");
        g_clear_error(&err);
        return rc;
    }
    char *db = g_build_filename(j->copy_dir, "session.sqlite", NULL);
    char *dbwal = g_strdup_printf("%s-wal", db);
    int rc = 0;
    if (!copy_file(j->path, db) || !copy_file(wal, dbwal)) {
        rc = rig_fail(RIG_ERR_IO, "journal %s: cannot copy it and its WAL into %s to read them: %s", j->path,
                      j->copy_dir, strerror(errno));
    } else if (sqlite3_open_v2(db, &j->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_FULLMUTEX, NULL) != SQLITE_OK ||
               sqlite3_exec(j->db, "SELECT count(*) FROM sqlite_master", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot read it with its WAL (a private copy)");
    }
    g_free(db);
    g_free(dbwal);
    return rc;
}

static int open_immutable(rig_journal_t *j)
{
    char *uri = immutable_uri(j->path);
    int rc = 0;
    if (sqlite3_open_v2(uri, &j->db, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI | SQLITE_OPEN_FULLMUTEX, NULL) !=
            SQLITE_OK ||
        sqlite3_exec(j->db, "SELECT count(*) FROM sqlite_master", NULL, NULL, NULL) != SQLITE_OK)
        rc = jfail(j, "cannot read (opened immutable: it or its directory cannot be written)");
    g_free(uri);
    return rc;
}

// A reader's connection (see the top of the file): SQLite's read-only open
// where a WAL holds commits or the journal could be written (a writer may
// come), else immutable; a WAL SQLite cannot read in place (no -shm, and none
// can be made) through a private copy.
static int open_read(rig_journal_t *j, const char *dir)
{
    struct stat st;
    if (access(j->path, R_OK) != 0 || stat(j->path, &st) != 0)
        return rig_fail(RIG_ERR_IO, "journal %s: cannot read: %s", j->path, strerror(errno));
    char *wal = g_strdup_printf("%s-wal", j->path);
    struct stat ws;
    bool wal_commits = stat(wal, &ws) == 0 && ws.st_size > 0;
    bool writable = access(dir, W_OK) == 0 && access(j->path, W_OK) == 0 && (st.st_mode & 0222);
    int rc = 0;
    if (!wal_commits && !writable) {
        rc = open_immutable(j);
        goto done;
    }
    if (sqlite3_open_v2(j->path, &j->db, SQLITE_OPEN_READONLY | SQLITE_OPEN_FULLMUTEX, NULL) == SQLITE_OK) {
        sqlite3_busy_timeout(j->db, 10000);
        if (sqlite3_exec(j->db, "SELECT count(*) FROM sqlite_master", NULL, NULL, NULL) == SQLITE_OK) goto done;
    }
    int code = j->db ? sqlite3_extended_errcode(j->db) & 0xff : SQLITE_NOMEM;
    if (code != SQLITE_READONLY && code != SQLITE_CANTOPEN) {   // damaged, not a database, ...
        rc = jfail(j, "cannot read");
        goto done;
    }
    sqlite3_close(j->db);   // SQLite cannot create the -wal or -shm file here
    j->db = NULL;
    rc = wal_commits ? open_copy(j, wal) : open_immutable(j);
done:
    g_free(wal);
    return rc;
}

// The writer's connection: read-write, WAL, synchronous FULL.
static int open_write(rig_journal_t *j, const char *dir, bool create)
{
    if (access(dir, W_OK) != 0)
        return rig_fail(RIG_ERR_IO, "%s cannot be written (%s): a session is captured or continued only where it "
                        "can be written (its readers need no write access); copy it to a writable place",
                        dir, strerror(errno));
    if (sqlite3_open_v2(j->path, &j->db, SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) |
                        SQLITE_OPEN_FULLMUTEX, NULL) != SQLITE_OK)
        return jfail(j, "cannot open");
    sqlite3_busy_timeout(j->db, 10000);
    if (sqlite3_exec(j->db, "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL; PRAGMA foreign_keys=ON;", NULL,
                     NULL, NULL) != SQLITE_OK)
        return jfail(j, "cannot set WAL mode");
    return 0;
}

// The journal's schema version, checked: 1 .. SCHEMA_VERSION into *v.
static int check_version(rig_journal_t *j, int *v)
{
    sqlite3_stmt *s = NULL;
    *v = -1;
    int prc = sqlite3_prepare_v2(j->db, "SELECT version FROM schema_version", -1, &s, NULL), st = SQLITE_DONE;
    if (prc == SQLITE_OK && (st = sqlite3_step(s)) == SQLITE_ROW) *v = sqlite3_column_int(s, 0);
    sqlite3_finalize(s);
    int code = sqlite3_extended_errcode(j->db) & 0xff;
    if ((prc != SQLITE_OK || (st != SQLITE_ROW && st != SQLITE_DONE)) && code != SQLITE_ERROR)
        return jfail(j, "cannot read the schema version");   // damaged, I/O error (not: no such table)
    if (*v < 1)
        return rig_fail(RIG_ERR_PROTOCOL, "journal %s: no schema version (not a refl session journal?); this "
                        "refl reads versions 1 to %d", j->path, SCHEMA_VERSION);
    if (*v > SCHEMA_VERSION)
        return rig_fail(RIG_ERR_PROTOCOL, "journal %s: schema version %d, written by a newer refl (this refl "
                        "reads versions 1 to %d)", j->path, *v, SCHEMA_VERSION);
    return 0;
}

static int open_db(rig_journal_t **out, const char *dir, journal_open_t how)
{
    *out = NULL;
    rig_journal_t *j = calloc(1, sizeof *j);
    if (!j) return rig_fail(RIG_ERR_NO_MEM, "journal: out of memory");
    pthread_mutex_init(&j->lock, NULL);
    j->path = g_strdup_printf("%s/session.sqlite", dir);
    struct stat st;
    bool exists = stat(j->path, &st) == 0;
    int rc = 0, v = 0;
    if (how == JOURNAL_CREATE && exists) {
        rc = rig_fail(RIG_ERR_INVALID, "%s already holds a session: continue it with refl capture --resume %s, or "
                      "choose another -o DIR", dir, dir);
        goto fail;
    }
    if (how != JOURNAL_CREATE && !exists) {
        rc = rig_fail(RIG_ERR_NO_DEVICE, "%s: no session here (no session.sqlite)", dir);
        goto fail;
    }
    if ((rc = how == JOURNAL_READ ? open_read(j, dir) : open_write(j, dir, how == JOURNAL_CREATE))) goto fail;
    if (how != JOURNAL_CREATE && (rc = check_version(j, &v))) goto fail;
    if (how == JOURNAL_RESUME && v == 1 && (rc = migrate_v1(j))) goto fail;
    *out = j;
    return 0;
fail:
    rig_journal_close(j);
    return rc;
}

int rig_journal_open(rig_journal_t **out, const char *dir) { return open_db(out, dir, JOURNAL_READ); }

int rig_journal_resume(rig_journal_t **out, const char *dir) { return open_db(out, dir, JOURNAL_RESUME); }

void rig_journal_close(rig_journal_t *j)
{
    if (!j) return;
    if (j->db) sqlite3_close(j->db);
    remove_copy(j);
    pthread_mutex_destroy(&j->lock);
    g_free(j->path);
    free(j);
}

int rig_journal_create(rig_journal_t **out, const char *dir, const rig_plan_t *p, const char *rig_path,
                       const char *rig_text, const char *rig_sha256, const char *session_json)
{
    rig_journal_t *j = NULL;
    int rc = open_db(&j, dir, JOURNAL_CREATE);
    if (rc) return rc;
    sqlite3_stmt *s = NULL;
    char now[40];
    model_utc_text(model_realtime_s(), now);
    char *frames = frames_sql(FRAMES_CREATE, NULL);
    bool made = sqlite3_exec(j->db, "BEGIN", NULL, NULL, NULL) == SQLITE_OK &&
                sqlite3_exec(j->db, schema, NULL, NULL, NULL) == SQLITE_OK &&
                sqlite3_exec(j->db, frames, NULL, NULL, NULL) == SQLITE_OK &&
                sqlite3_exec(j->db, schema_events, NULL, NULL, NULL) == SQLITE_OK;
    g_free(frames);
    if (!made) {
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
                           "angle_deg,lamps,exposure_us,gain,note) VALUES(?,?,?,?,?,?,?,?,?,?,?,?)", -1, &s, NULL) !=
        SQLITE_OK) {
        rc = jfail(j, "cannot write the steps");
        goto fail;
    }
    for (int i = 0; i < p->nsteps; i++) {
        const rig_step_t *st = &p->steps[i];
        sqlite3_reset(s);
        sqlite3_bind_int(s, 1, st->index);
        sqlite3_bind_text(s, 2, st->kind == RIG_STEP_DARK ? "dark" : st->kind == RIG_STEP_OPERATOR ? "operator"
                                                                                             : "light",
                          -1, SQLITE_STATIC);
        sqlite3_bind_int(s, 3, st->angle_index);
        sqlite3_bind_int(s, 4, st->lamp_set);
        sqlite3_bind_int(s, 5, st->exposure_index);
        sqlite3_bind_int(s, 6, st->repeat);
        sqlite3_bind_int(s, 7, st->group);
        sqlite3_bind_double(s, 8, st->angle_deg);
        sqlite3_bind_text(s, 9, st->lamps, -1, SQLITE_TRANSIENT);
        sqlite3_bind_double(s, 10, st->exposure_us);
        sqlite3_bind_double(s, 11, st->gain);
        if (st->kind == RIG_STEP_OPERATOR && st->op >= 0 && st->op < p->nops)
            sqlite3_bind_text(s, 12, p->ops[st->op].instruction, -1, SQLITE_TRANSIENT);
        else
            sqlite3_bind_null(s, 12);
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
        char *v[3] = { col_text(s, 0), col_text(s, 1), col_text(s, 2) };
        if (!v[0] || !v[1] || !v[2]) {
            rc = rig_fail(RIG_ERR_NO_MEM, "journal %s: out of memory", j->path);
            for (int i = 0; i < 3; i++) free(v[i]);
        } else {
            char **out[3] = { path, text, sha256 };
            for (int i = 0; i < 3; i++) {
                if (out[i]) *out[i] = v[i];
                else free(v[i]);
            }
        }
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
    else if (!(*json = col_text(s, 0)))
        rc = rig_fail(RIG_ERR_NO_MEM, "journal %s: out of memory", j->path);
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

int rig_journal_integrity(rig_journal_t *j, char **result)
{
    *result = NULL;
    sqlite3_stmt *s = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "PRAGMA integrity_check(20)", -1, &s, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot run PRAGMA integrity_check");
    } else {
        GString *g = g_string_new(NULL);
        int st;
        while ((st = sqlite3_step(s)) == SQLITE_ROW) {
            const unsigned char *t = sqlite3_column_text(s, 0);
            g_string_append_printf(g, "%s%s", g->len ? "; " : "", t ? (const char *)t : "");
        }
        for (char *c = g->str; *c; c++)   // one line: SQLite's findings may hold line breaks
            if (*c == '\n') *c = ' ';
        if (st != SQLITE_DONE) {
            g_string_append_printf(g, "%s%s", g->len ? "; " : "", sqlite3_errmsg(j->db));
        }
        *result = g_string_free(g, FALSE);
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return rc;
}

int rig_journal_check(rig_journal_t *j)
{
    char *found = NULL;
    int rc = rig_journal_integrity(j, &found);
    if (!rc && strcmp(found, "ok"))
        rc = rig_fail(RIG_ERR_IO, "journal %s fails SQLite's integrity check: %s (the journal is damaged: sqlite3 %s "
                      ".recover > recovered.sql saves what can be read)", j->path, found, j->path);
    g_free(found);
    return rc;
}

const char *rig_journal_path(const rig_journal_t *j) { return j->path; }

int rig_journal_steps(rig_journal_t *j, rig_step_t **steps, char **status, int *n)
{
    *steps = NULL;
    *status = NULL;
    *n = 0;
    int total = rig_journal_nsteps(j);
    if (total < 0) return jfail(j, "cannot read the steps");
    rig_step_t *st = calloc((size_t)total + 1, sizeof *st);
    char *stat = calloc((size_t)total + 1, 1);
    if (!st || !stat) {
        free(st);
        free(stat);
        return rig_fail(RIG_ERR_NO_MEM, "journal %s: out of memory for %d steps", j->path, total);
    }
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
            const char *kind = (const char *)sqlite3_column_text(s, 1);
            t->kind = !strcmp(kind, "dark") ? RIG_STEP_DARK : !strcmp(kind, "operator") ? RIG_STEP_OPERATOR
                                                                                         : RIG_STEP_LIGHT;
            t->op = -1;
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
    sqlite3_stmt *s = NULL;
    int rc = 0, k = 0, total = -1;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT COUNT(*) FROM frames", -1, &s, NULL) == SQLITE_OK &&
        sqlite3_step(s) == SQLITE_ROW)
        total = sqlite3_column_int(s, 0);
    sqlite3_finalize(s);
    s = NULL;
    pthread_mutex_unlock(&j->lock);
    if (total < 0) return jfail(j, "cannot read the frames");
    rig_frame_row_t *r = calloc((size_t)total + 1, sizeof *r);
    if (!r) return rig_fail(RIG_ERR_NO_MEM, "journal %s: out of memory for %d frames", j->path, total);
    pthread_mutex_lock(&j->lock);
    char *sql = frames_sql(FRAMES_SELECT, j->db);
    if (sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot read the frames");
    } else {
        while (k < total && sqlite3_step(s) == SQLITE_ROW) frame_read(s, &r[k++]);
    }
    g_free(sql);
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

// A journal without some frame columns, written to: they are added (its
// earlier frames hold NULL there). Within the frame's transaction.
static int add_frame_columns(rig_journal_t *j)
{
    if (j->frame_columns_ok) return 0;
    for (int i = 0; i < NFRAME_COLUMNS; i++) {
        if (frames_has_column(j->db, frame_columns[i].column)) continue;
        char *sql = g_strdup_printf("ALTER TABLE frames ADD COLUMN %s %.*s", frame_columns[i].column,
                                    (int)strcspn(frame_columns[i].decl, " "), frame_columns[i].decl);
        int ok = sqlite3_exec(j->db, sql, NULL, NULL, NULL);
        g_free(sql);
        if (ok != SQLITE_OK) return jfail(j, "cannot add a missing frame column");
    }
    j->frame_columns_ok = true;
    return 0;
}

int rig_journal_frame_done(rig_journal_t *j, const rig_frame_row_t *f, bool step_done)
{
    sqlite3_stmt *s = NULL, *u = NULL;
    int rc = 0;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_exec(j->db, "BEGIN IMMEDIATE", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot begin a frame transaction");
        goto done;
    }
    if ((rc = add_frame_columns(j))) goto rollback;
    char *sql = frames_sql(FRAMES_INSERT, NULL);
    bool prepared = sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) == SQLITE_OK &&
                    sqlite3_prepare_v2(j->db, "UPDATE steps SET status='done' WHERE idx=? AND status='pending'", -1,
                                       &u, NULL) == SQLITE_OK;
    g_free(sql);
    if (!prepared) {
        rc = jfail(j, "cannot record a frame");
        goto rollback;
    }
    frame_bind(s, f);
    sqlite3_bind_int(u, 1, f->step);
    if (sqlite3_step(s) != SQLITE_DONE ||
        (step_done && (sqlite3_step(u) != SQLITE_DONE || sqlite3_changes(j->db) != 1))) {
        rc = jfail(j, "cannot record a frame (a step's camera recorded twice?)");
        goto rollback;
    }
    if (sqlite3_exec(j->db, "COMMIT", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot commit a frame");
        goto rollback;
    }
    goto done;
rollback:
    sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
    j->frame_columns_ok = false;   // an added column went with the transaction
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

char *rig_journal_step_note(rig_journal_t *j, int step)
{
    sqlite3_stmt *s = NULL;
    char *note = NULL;
    pthread_mutex_lock(&j->lock);
    if (sqlite3_prepare_v2(j->db, "SELECT note FROM steps WHERE idx=?", -1, &s, NULL) == SQLITE_OK) {
        sqlite3_bind_int(s, 1, step);
        if (sqlite3_step(s) == SQLITE_ROW && sqlite3_column_type(s, 0) != SQLITE_NULL) note = col_text(s, 0);
    }
    sqlite3_finalize(s);
    pthread_mutex_unlock(&j->lock);
    return note;
}

int rig_journal_operator_done(rig_journal_t *j, int step, const char *how)
{
    sqlite3_stmt *u = NULL, *e = NULL;
    int rc = 0;
    char now[40];
    model_utc_text(model_realtime_s(), now);
    pthread_mutex_lock(&j->lock);
    if (sqlite3_exec(j->db, "BEGIN IMMEDIATE", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot begin an operator transaction");
        goto done;
    }
    if (sqlite3_prepare_v2(j->db, "UPDATE steps SET status='done' WHERE idx=? AND status='pending' AND "
                           "kind='operator'", -1, &u, NULL) != SQLITE_OK ||
        sqlite3_prepare_v2(j->db, "INSERT INTO events(t_utc, kind, message, step) VALUES(?,'operator',?,?)", -1, &e,
                           NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot record an operator step");
        goto rollback;
    }
    sqlite3_bind_int(u, 1, step);
    sqlite3_bind_text(e, 1, now, -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(e, 2, how, -1, SQLITE_TRANSIENT);
    sqlite3_bind_int(e, 3, step);
    if (sqlite3_step(u) != SQLITE_DONE || sqlite3_changes(j->db) != 1 || sqlite3_step(e) != SQLITE_DONE) {
        rc = jfail(j, "cannot record an operator step (not a pending operator step?)");
        goto rollback;
    }
    if (sqlite3_exec(j->db, "COMMIT", NULL, NULL, NULL) != SQLITE_OK) {
        rc = jfail(j, "cannot commit an operator step");
        goto rollback;
    }
    goto done;
rollback:
    sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
done:
    sqlite3_finalize(u);
    sqlite3_finalize(e);
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

// ---------------------------------------------------------------------------
// `refl session export`, from RIG_FRAME_COLUMNS

#define CSV_HEAD_INT(name)  #name ","
#define CSV_HEAD_REAL(name) #name ","
#define CSV_HEAD_TEXT(name) #name ","
#define CSV_HEAD_U64(name)  #name ","
#define CSV_HEAD_UTC(name)
#define CSV_HEAD_(kind, name, column, decl, csv, size) CSV_HEAD_##kind(name)

// A text field: quoted (quotes doubled) when it holds a comma, quote or line break.
static void csv_text(FILE *f, const char *sep, const char *s)
{
    fputs(sep, f);
    if (!strpbrk(s, ",\"\n\r")) {
        fputs(s, f);
        return;
    }
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '"') fputc('"', f);
        fputc(*s, f);
    }
    fputc('"', f);
}

void rig_frame_rows_write_csv(FILE *f, const rig_frame_row_t *rows, int n)
{
    static const char head[] = RIG_FRAME_COLUMNS(CSV_HEAD_);
    fprintf(f, "%.*s\n", (int)sizeof head - 2, head);   // without the last ','
    for (int i = 0; i < n; i++) {
        const rig_frame_row_t *r = &rows[i];
        const char *sep = "";
#define CSV_INT(name, fmt)  fprintf(f, "%s" fmt, sep, r->name), sep = ",";
#define CSV_REAL(name, fmt) fprintf(f, "%s" fmt, sep, r->name), sep = ",";
#define CSV_TEXT(name, fmt) csv_text(f, sep, r->name), sep = ",";
#define CSV_U64(name, fmt)  fprintf(f, "%s" fmt, sep, (unsigned long long)r->name), sep = ",";
#define CSV_UTC(name, fmt)
#define CSV_(kind, name, column, decl, csv, size) CSV_##kind(name, csv)
        RIG_FRAME_COLUMNS(CSV_)
#undef CSV_
        fputc('\n', f);
    }
}

json_t *rig_frame_rows_json(const rig_frame_row_t *rows, int n)
{
    json_t *doc = json_object(), *a = json_array();
    if (!doc || !a) {
        json_decref(doc);
        json_decref(a);
        return NULL;
    }
    model_json_set_format(doc, RIG_SESSION_FRAMES_FORMAT, RIG_SESSION_FRAMES_VERSION);
    if (json_object_set_new(doc, "frames", a)) {   // (takes a, also when it fails)
        json_decref(doc);
        return NULL;
    }
    for (int i = 0; i < n; i++) {
        const rig_frame_row_t *r = &rows[i];
        json_t *o = json_object();
        if (!o || json_array_append_new(a, o)) {
            json_decref(doc);
            return NULL;
        }
#define JSON_INT(name)  json_object_set_new(o, #name, json_integer(r->name));
#define JSON_REAL(name) json_object_set_new(o, #name, model_json_number(r->name));
#define JSON_TEXT(name) json_object_set_new(o, #name, json_string(r->name));
#define JSON_U64(name)  json_object_set_new(o, #name, json_integer((json_int_t)r->name));
#define JSON_UTC(name)
#define JSON_(kind, name, column, decl, csv, size) JSON_##kind(name)
        RIG_FRAME_COLUMNS(JSON_)
#undef JSON_
    }
    return doc;
}

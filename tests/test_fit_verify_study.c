// tests/test_fit_verify_study.c — `refl verify --study` through a chain's
// calibrations and priors, in shards, and `--study-merge` (fit/eval/study.c):
// the merged shards equal the unsharded run exactly; bad merges are refused
// with the directory or file:line named.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model/model.h"
#include "tests/test.h"

// A chain's calibration directory as refl calib writes it: the truth's camera
// model, lamps.json with each lamp a few mm off the truth (as the lamp
// calibration finds them), gain.json (K, read noise, saturation at 0 dB) and
// white.json (kc*I per lamp, as refl calib white measured them on the matched rig).
static char *chain_calib(void)
{
    char src[4096];
    char *top = realpath(test_srcdir(), NULL);
    snprintf(src, sizeof src, "%s/examples/camera.cameramodel", top ? top : ".");
    free(top);
    char *cam = model_read_file(src, NULL);
    CHECK(cam != NULL);
    char *dir = g_strdup(test_path("cal"));
    g_mkdir_with_parents(dir, 0755);
    test_write("cal/camera.cameramodel", cam ? cam : "");
    free(cam);
    test_write("cal/lamps.json",
               "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [490.1, 176.5, 601.2], \"radius_mm\": 15},"
               " {\"name\": \"south\", \"position_mm\": [-51.0, -599.1, 478.8], \"radius_mm\": 15},"
               " {\"name\": \"west\", \"position_mm\": [-527.0, -190.2, 521.5], \"radius_mm\": 15},"
               " {\"name\": \"north\", \"position_mm\": [97.1, 368.0, 701.9], \"radius_mm\": 15},"
               " {\"name\": \"rim\", \"position_mm\": [-621.0, 66.0, 220.4], \"radius_mm\": 15}]}\n");
    test_write("cal/gain.json", "{\"gain_db\": 0, \"gain_unit\": \"dB\", \"system_gain_dn_per_e\": 0.25, "
                                "\"read_noise_e\": 6, \"saturation_dn\": 3920}\n");
    test_write("cal/white.json",
               "{\"albedo\": 0.99, \"lamps\": [{\"name\": \"east\", \"kc_I_per_us\": 309746.3},"
               " {\"name\": \"south\", \"kc_I_per_us\": 280660.8}, {\"name\": \"west\", \"kc_I_per_us\": 299996.2},"
               " {\"name\": \"north\", \"kc_I_per_us\": 348310.6}, {\"name\": \"rim\", \"kc_I_per_us\": 250041.8}]}\n");
    return dir;
}

// Priors files as refl fit material writes them (the means a few % off the truth).
static void chain_priors(char **ply, char **steel)
{
    *ply = g_strdup(test_write("priors_plywood.json",
        "{\"format\": \"refl priors 1\", \"materials\": [{\"name\": \"plywood\", \"model\": \"thesis_fit\", "
        "\"parameters\": [{\"name\": \"ks\", \"mean\": 0.0205, \"std\": 0.0006}, {\"name\": \"ns\", \"mean\": 8.1, "
        "\"std\": 0.25}, {\"name\": \"kd\", \"mean\": 0.161, \"std\": 0.005}]}]}\n"));
    *steel = g_strdup(test_write("priors_painted_steel.json",
        "{\"format\": \"refl priors 1\", \"materials\": [{\"name\": \"painted_steel\", \"model\": \"ggx\", "
        "\"parameters\": [{\"name\": \"kd\", \"mean\": 0.49, \"std\": 0.015}, {\"name\": \"ks\", \"mean\": 0.255, "
        "\"std\": 0.008}, {\"name\": \"alpha\", \"mean\": 0.151, \"std\": 0.0045}, {\"name\": \"F0\", \"mean\": "
        "0.04, \"std\": 0.0012}]}]}\n"));
}

__attribute__((noinline)) static char *slurp(const char *dir, const char *name)
{
    char *p = g_strdup_printf("%s/%s", dir, name), *t = NULL;
    g_file_get_contents(p, &t, NULL, NULL);
    g_free(p);
    return t;
}

// refl verify ARGS...; its exit status, stderr kept in *err (g_free).
static int verify(char **err, const char *const *args)
{
    const char *argv[32];
    int n = 0;
    argv[n++] = test_refl();
    argv[n++] = "verify";
    for (int i = 0; args[i] && n < 31; i++) argv[n++] = args[i];
    argv[n] = NULL;
    char *out = NULL;
    int rc = test_run(argv, 600, &out, err);
    g_free(out);
    return rc;
}

// The study of 2 cases in the default configuration through the chain's
// calibrations and priors: complete, with the report page, 17 descriptions
// (the correct one, 13 corruptions, the part placed off three ways) in
// study.csv, summary and ROC in study.json computed by refl, the chain's
// inputs in its design. Its shards 1/2 and 2/2 hold case 0 and case 1 only
// and no results; merged they give study.csv byte for byte and study.json's
// results and design exactly. A merge that lacks a shard, repeats one, mixes
// in another study's or reads a bad row is refused with the reason.
TEST_LONG(verify_study_shards_merge_equal_unsharded)
{
    char *cal = chain_calib(), *ply, *steel, *err = NULL;
    chain_priors(&ply, &steel);
    char *whole = g_strdup(test_path("whole")), *merged = g_strdup(test_path("par"));
    char s1buf[4200], s2buf[4200];
    const char *s1 = s1buf, *s2 = s2buf;
    const char *common[] = { "--study", "--cases", "2", "--configs", "priors+maps", "--calib", cal, "--priors", ply,
                             steel, "--threads", "2", NULL };
    const char *a0[32];
    int n = 0;
    for (; common[n]; n++) a0[n] = common[n];
    a0[n] = "-o", a0[n + 1] = whole, a0[n + 2] = NULL;
    int rc = verify(&err, a0);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(err);
    // the shards side by side with GNU parallel (scripts/study-shards): shard K in par/shards/K, merged in par
    const char *sd = getenv("REFL_SCRIPTS_DIR");
    char *shards_sh = g_strdup_printf("%s/study-shards", sd ? sd : "scripts"), *refl_env = g_strdup_printf(
        "REFL=%s", test_refl());
    const char *ps[40] = { "/usr/bin/env", refl_env, shards_sh, "-j", "2", "2", merged, "--" };
    int m = 8;
    for (int i = 1; common[i] && m < 38; i++) ps[m++] = common[i];   // (the script says --study)
    ps[m] = NULL;
    char *out = NULL;
    rc = test_run(ps, 600, &out, &err);
    CHECK_MSG(rc == 0, "study-shards: %s", err);
    g_free(out);
    g_free(err);
    g_free(shards_sh);
    snprintf(s1buf, sizeof s1buf, "%s/shards/1", merged);
    snprintf(s2buf, sizeof s2buf, "%s/shards/2", merged);
    char *cw = slurp(whole, "study.csv"), *cm = slurp(merged, "study.csv"), *c1 = slurp(s1, "study.csv");
    char *html = slurp(whole, "index.html"), *html_m = slurp(merged, "index.html");
    CHECK(cw && cm && c1 && html && html_m);
    if (cw && cm) CHECK_MSG(!strcmp(cw, cm), "merged study.csv differs from the unsharded one");
    int rows = 0, placed = 0, case1_in_s1 = 0;
    for (char *p = cw; p && (p = strchr(p, '\n')); p++) rows += p[1] != 0;
    for (char *p = cw; p && (p = strstr(p, ",placed,")); p++) placed++;
    for (char *p = c1; p && (p = strchr(p, '\n')) && p[1]; p++) {   // each row's fourth field: its case
        const char *f = p + 1;
        for (int k = 0; k < 3 && f; k++) f = strchr(f, ',') ? strchr(f, ',') + 1 : NULL;
        case1_in_s1 += f && !strncmp(f, "1,", 2);
    }
    CHECK_MSG(rows == 2 * 17, "%d rows: want 2 cases x 17 descriptions", rows);
    CHECK(placed == 2 * 3);
    CHECK_MSG(case1_in_s1 == 0, "shard 1/2 has case 1");
    char *jp[3] = { g_strdup_printf("%s/study.json", whole), g_strdup_printf("%s/study.json", merged),
                    g_strdup_printf("%s/study.json", s1) };
    json_t *jw = json_load_file(jp[0], 0, NULL), *jm = json_load_file(jp[1], 0, NULL), *j1 = json_load_file(jp[2], 0, NULL);
    CHECK(jw && jm && j1);
    if (jw && jm && j1) {
        json_t *rw = json_object_get(jw, "results"), *rm = json_object_get(jm, "results");
        CHECK(json_is_true(json_object_get(jw, "complete")) && json_is_true(json_object_get(jm, "complete")));
        CHECK(!json_is_true(json_object_get(j1, "complete")) && !json_object_get(j1, "results"));
        CHECK(json_equal(rw, rm));
        CHECK(json_equal(json_object_get(jw, "design"), json_object_get(jm, "design")));
        CHECK(json_array_size(json_object_get(rw, "summary")) == 16);
        CHECK(json_array_size(json_object_get(rw, "roc")) == 16);
        // the I-stiffener: scored far above the correct description in both cases
        json_t *s0 = json_array_get(json_object_get(rw, "summary"), 0);
        CHECK(!strcmp(json_string_value(json_object_get(s0, "description")), "I-stiffener"));
        CHECK_NEAR(json_number_value(json_object_get(s0, "auc")), 1.0, 1e-12);
        // the chain's calibrations and priors are the study's inputs
        const char *ds = json_dumps(json_object_get(jw, "design"), 0);
        CHECK(ds && strstr(ds, "the chain's (--calib)") && strstr(ds, "\"white\"") && strstr(ds, "\"priors\""));
        free((void *)ds);
        CHECK(json_array_size(json_object_get(json_object_get(jm, "provenance"), "merged_from")) == 2);
    }
    json_decref(jw);
    json_decref(jm);
    json_decref(j1);

    // Slurm (scripts/study-slurm): submit makes the array of 2 and the merge after it (sbatch stands in: it
    // records its arguments); task 2 of the array runs shard 2/2; with shard 1 beside it the merge job
    // gives the same study again
    char *slurm = g_strdup(test_path("slurm")), *slurm_sh = g_strdup_printf("%s/study-slurm", sd ? sd : "scripts");
    char *bindir = g_strdup(test_path("fakebin")), *path_env = g_strdup_printf("PATH=%s:%s", bindir, getenv("PATH"));
    g_mkdir_with_parents(bindir, 0755);
    char *sb = g_strdup(test_write("fakebin/sbatch", "#!/bin/sh\necho \"$*\" >> \"$(dirname \"$0\")/calls\"\n"
                                                     "echo 4711\n"));
    chmod(sb, 0755);
    const char *sub[40] = { "/usr/bin/env", path_env, refl_env, slurm_sh, "submit", "2", slurm, "--" };
    m = 8;
    for (int i = 1; common[i] && m < 38; i++) sub[m++] = common[i];
    sub[m] = NULL;
    rc = test_run(sub, 60, &out, &err);
    CHECK_MSG(rc == 0 && out && strstr(out, "4711"), "study-slurm submit: %s %s", out, err);
    g_free(out);
    g_free(err);
    char *calls = slurp(bindir, "calls");
    CHECK_MSG(calls && strstr(calls, "--array=1-2") && strstr(calls, " shard ") &&
              strstr(calls, "--dependency=afterok:4711") && strstr(calls, " merge "), "sbatch got: %s", calls);
    g_free(calls);
    const char *task[40] = { "/usr/bin/env", refl_env, "SLURM_ARRAY_TASK_ID=2", "SLURM_ARRAY_TASK_MIN=1",
                             "SLURM_ARRAY_TASK_COUNT=2", "SLURM_CPUS_PER_TASK=2", slurm_sh, "shard", slurm, "--" };
    m = 10;
    for (int i = 1; common[i] && m < 38; i++)
        if (strcmp(common[i], "--threads") && (i == 0 || strcmp(common[i - 1], "--threads"))) task[m++] = common[i];
    task[m] = NULL;
    rc = test_run(task, 600, &out, &err);
    CHECK_MSG(rc == 0, "study-slurm shard: %s", err);
    g_free(out);
    g_free(err);
    char *dst = g_strdup_printf("%s/shards/", slurm);
    rc = test_run((const char *const[]){ "cp", "-r", s1, dst, NULL }, 60, &out, &err);
    CHECK_MSG(rc == 0, "cp: %s", err);
    g_free(out);
    g_free(err);
    g_free(dst);
    rc = test_run((const char *const[]){ "/usr/bin/env", refl_env, slurm_sh, "merge", slurm, NULL }, 120, &out, &err);
    CHECK_MSG(rc == 0, "study-slurm merge: %s", err);
    g_free(out);
    g_free(err);
    char *cs = slurp(slurm, "study.csv");
    CHECK_MSG(cs && cw && !strcmp(cs, cw), "the Slurm study's study.csv differs from the unsharded one");
    g_free(cs);
    g_free(slurm);
    g_free(slurm_sh);
    g_free(bindir);
    g_free(path_env);
    g_free(sb);

    // refused merges
    rc = verify(&err, (const char *const[]){ "--study-merge", s1, "-o", test_path("m2"), NULL });
    CHECK_MSG(rc != 0 && err && strstr(err, "case 1") && strstr(err, "none of the shards"), "%s", err);
    g_free(err);
    rc = verify(&err, (const char *const[]){ "--study-merge", s1, s1, s2, "-o", test_path("m3"), NULL });
    CHECK_MSG(rc != 0 && err && strstr(err, "already in another shard"), "%s", err);
    g_free(err);
    // another study's shard: its design names other inputs
    char *s2b = g_strdup(test_path("s2b"));
    g_mkdir_with_parents(s2b, 0755);
    char *c2 = slurp(s2, "study.csv"), *j2 = slurp(s2, "study.json");
    if (c2 && j2) {
        char *cases_at = strstr(j2, "\"cases\": 2");
        CHECK(cases_at != NULL);
        if (cases_at) cases_at[9] = '3';
        test_write("s2b/study.json", j2);
        test_write("s2b/study.csv", c2);
    }
    rc = verify(&err, (const char *const[]){ "--study-merge", s1, s2b, "-o", test_path("m4"), NULL });
    CHECK_MSG(rc != 0 && err && strstr(err, "s2b/study.json") && strstr(err, "differs"), "%s", err);
    g_free(err);
    // a bad row: file and line named
    if (c2 && j2) {
        char *j2orig = slurp(s2, "study.json");
        test_write("s2b/study.json", j2orig ? j2orig : "");
        g_free(j2orig);
        static const char row[] = "\npriors+maps,missing,wrong,1,";
        char *row_at = strstr(c2, row);
        CHECK(row_at != NULL);
        if (row_at) row_at[strlen(row)] = 'x';
        test_write("s2b/study.csv", c2);
        rc = verify(&err, (const char *const[]){ "--study-merge", s1, s2b, "-o", test_path("m5"), NULL });
        CHECK_MSG(rc != 0 && err && strstr(err, "s2b/study.csv:4"), "%s", err);
        g_free(err);
    }
    // usage errors
    rc = verify(&err, (const char *const[]){ "--study", "--cases", "2", "--shard", "3/2", "-o", test_path("x"), NULL });
    CHECK_MSG(rc == 2 && err && strstr(err, "--shard"), "%s", err);
    g_free(err);
    rc = verify(&err, (const char *const[]){ "--study", "--cases", "2", "--configs", "best", "-o", test_path("x"),
                                             NULL });
    CHECK_MSG(rc != 0 && err && strstr(err, "'best'"), "%s", err);
    g_free(err);
    for (int i = 0; i < 3; i++) g_free(jp[i]);
    g_free(c2);
    g_free(j2);
    g_free(s2b);
    g_free(cw);
    g_free(cm);
    g_free(c1);
    g_free(html);
    g_free(html_m);
    g_free(cal);
    g_free(ply);
    g_free(steel);
    g_free(whole);
    g_free(merged);
    g_free(refl_env);
}

// The study that registers each case's descriptions (--placement-tolerance-mm
// 3 --placement-tolerance-deg 2), as two shards merged: placement.csv has one
// row per case and description, the parts placed off are registered where
// they lie (within 0.1 mm, 0.05 deg of the offset given to the rig), the
// correct description at the nominal pose, and the merge keeps every shard's
// row; the design names the tolerance.
TEST_LONG(verify_study_registered_placement_sharded)
{
    char *dir[3] = { g_strdup(test_path("reg1")), g_strdup(test_path("reg2")), g_strdup(test_path("regm")) };
    char *err = NULL;
    for (int k = 0; k < 2; k++) {
        // (the windows near edges skipped: each registered description's views are made anew, and what is
        // tested here is the registration and the merge)
        const char *a[] = { "--study", "--cases", "2", "--configs", "priors+maps", "--placement-tolerance-mm", "3",
                            "--placement-tolerance-deg", "2", "--skip-edge-windows", "--shard", k ? "2/2" : "1/2",
                            "-o", dir[k], NULL };
        int rc = verify(&err, a);
        CHECK_MSG(rc == 0, "shard %d: %s", k + 1, err);
        g_free(err);
    }
    const char *m[] = { "--study-merge", dir[0], dir[1], "-o", dir[2], NULL };
    int rc = verify(&err, m);
    CHECK_MSG(rc == 0, "merge: %s", err);
    g_free(err);
    char *p1 = slurp(dir[0], "placement.csv"), *p2 = slurp(dir[1], "placement.csv"), *pm = slurp(dir[2], "placement.csv");
    CHECK(p1 && p2 && pm);
    // every shard's row in the merge, and only those
    int rows = 0, found = 0;
    char **lines = pm ? g_strsplit(pm, "\n", -1) : NULL;
    for (int i = 1; lines && lines[i]; i++) {
        if (!lines[i][0]) continue;
        rows++;
        char *key = g_strdup_printf("\n%s\n", lines[i]);
        found += (p1 && strstr(p1, key)) || (p2 && strstr(p2, key));
        g_free(key);
        char desc[64];
        int c;
        double dx, dy, turn, agree;
        if (sscanf(lines[i], "%63[^,],%d,%lf,%lf,%lf,%lf", desc, &c, &dx, &dy, &turn, &agree) != 6) continue;
        const double mm[3] = { 1, 2, 3 }, deg[3] = { 0.5, 1, 2 };
        static const char *pl[3] = { "placed 1 mm 0.5 deg", "placed 2 mm 1 deg", "placed 3 mm 2 deg" };
        for (int k = 0; k < 3; k++)
            if (!strcmp(desc, pl[k])) {
                CHECK_MSG(fabs(dx - mm[k] * cos(M_PI / 6)) < 0.1 && fabs(dy - mm[k] * sin(M_PI / 6)) < 0.1 &&
                              fabs(turn - deg[k]) < 0.05, "%s case %d: registered (%g, %g) mm, %g deg", desc, c, dx,
                          dy, turn);
            }
        if (!strcmp(desc, "correct"))
            CHECK_MSG(fabs(dx) < 0.1 && fabs(dy) < 0.1 && fabs(turn) < 0.05 && agree > 0.8, "correct case %d: "
                      "(%g, %g) mm, %g deg, agreement %g", c, dx, dy, turn, agree);
    }
    CHECK_MSG(rows == 2 * 17 && found == rows, "%d rows (want 34), %d of them from the shards", rows, found);
    g_strfreev(lines);
    char *jp = g_strdup_printf("%s/study.json", dir[2]);
    json_t *j = json_load_file(jp, 0, NULL);
    json_t *t = j ? json_object_get(json_object_get(j, "design"), "placement_tolerance") : NULL;
    CHECK(t && json_real_value(json_object_get(t, "mm")) == 3 && json_real_value(json_object_get(t, "deg")) == 2);
    CHECK(j && json_is_true(json_object_get(j, "complete")));
    json_decref(j);
    g_free(jp);
    g_free(p1);
    g_free(p2);
    g_free(pm);
    for (int k = 0; k < 3; k++) g_free(dir[k]);
}

// A shard of one case (one configuration, the correct description and one
// corruption) in DIR: study.json with the design (head: what precedes it,
// e.g. its format and version) and study.csv.
static const char *tiny_shard(const char *dir, const char *head)
{
    const char *d = test_path(dir);
    g_mkdir_with_parents(d, 0755);
    char *j = g_strdup_printf("%s/study.json", d), *c = g_strdup_printf("%s/study.csv", d);
    char *text = g_strdup_printf("{%s\"design\": {\"cases\": 1, \"configurations\": [\"priors\"], \"descriptions\": "
                                 "[{\"description\": \"correct\", \"expected\": \"correct\"}, {\"description\": "
                                 "\"missing\", \"expected\": \"wrong\"}]}}", head);
    CHECK(g_file_set_contents(j, text, -1, NULL));
    CHECK(g_file_set_contents(c, "config,description,expected,case,score,verdict_correct,rms_z,median_abs_z\n"
                                 "priors,correct,correct,0,1.5,1,1.02,0.7\n"
                                 "priors,missing,wrong,0,900,1,3.5,2.1\n", -1, NULL));
    g_free(text);
    g_free(j);
    g_free(c);
    return d;
}

// study.json names its format: a shard without "format" and "version" reads
// as version 1 and merges (merged_from records the version), the merged
// study.json says refl-study 1; a newer version or another format is refused
// with both named.
TEST(verify_study_merge_format_versions)
{
    char *err = NULL, *out1 = g_strdup(test_path("out1")), *out2 = g_strdup(test_path("out2"));
    char *v1 = g_strdup(tiny_shard("v1", ""));
    const char *a1[] = { "--study-merge", v1, "-o", out1, "--no-report", NULL };
    int rc = verify(&err, a1);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(err);
    char *p = g_strdup_printf("%s/study.json", out1);
    json_t *doc = json_load_file(p, 0, NULL);
    CHECK(doc && !g_strcmp0(json_string_value(json_object_get(doc, "format")), "refl-study") &&
          json_integer_value(json_object_get(doc, "version")) == 1 && json_is_true(json_object_get(doc, "complete")));
    json_t *from = json_object_get(json_object_get(doc, "provenance"), "merged_from");
    CHECK(json_integer_value(json_object_get(json_array_get(from, 0), "version")) == 1);
    json_decref(doc);
    g_free(p);
    char *v2 = g_strdup(tiny_shard("v2", "\"format\": \"refl-study\", \"version\": 2, "));
    const char *a2[] = { "--study-merge", v2, "-o", out2, "--no-report", NULL };
    rc = verify(&err, a2);
    CHECK(rc != 0);
    CHECK_CONTAINS(err, "refl-study version 2");
    CHECK_CONTAINS(err, "versions 1 to 1");
    g_free(err);
    char *other = g_strdup(tiny_shard("other", "\"format\": \"refl-chain\", \"version\": 1, "));
    const char *a3[] = { "--study-merge", other, "-o", out2, "--no-report", NULL };
    rc = verify(&err, a3);
    CHECK(rc != 0);
    CHECK_CONTAINS(err, "a refl-chain file, not refl-study");
    g_free(err);
    g_free(v1);
    g_free(v2);
    g_free(other);
    g_free(out1);
    g_free(out2);
}

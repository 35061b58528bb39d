# refl — one non-recursive Makefile.
#   make          build bin/refl (installs missing Debian packages first)
#   make check    the tests but the long end-to-end ones, under 10 minutes on 2 cores ("N passed, N failed")
#   make check-long  the long ones: a lab day, calibrations and fits on the virtual rig (CI runs both)
#   make demo     the main job on the virtual rig
#   make study    the verification detection study through the lab day's calibrations and priors
#   make bench    performance figures, one "NAME: VALUE UNIT" line each
#   make asan     the tests under AddressSanitizer + UndefinedBehaviorSanitizer
#   make fuzz     fuzz the parsers with libFuzzer (FUZZ_SECONDS=60)
#   make fuzz-cameramodel   fuzz the .cameramodel reader alone (FUZZ_SECONDS=60)
#   make man      the manual pages from the commands' --help (build/man/man1)
#   make install  refl, its scripts, examples and manual pages under $(DESTDIR)$(PREFIX) (default /usr/local)
# WERROR=1 turns warnings into errors (CI sets it).

.DEFAULT_GOAL := all
BUILD ?= build
BIN   ?= bin
CC    ?= cc
CXX   ?= c++

# Libraries found through pkg-config; Embree 3 and mrcal ship no .pc file on
# Debian 12, so they are linked by name (scripts/install-deps installs them).
PKGS := glib-2.0 libpng libjpeg libtiff-4 jansson libftdi1 libusb-1.0 libgpiod aravis-0.8 sqlite3 zlib
# Only the tests link libumockdev (the simulated USB device of the APT tests).
TEST_PKGS := umockdev-1.0
# OpenCV 4 (calib/geometry/board_detect.cc only): its flags, and of its libraries the
# four refl calls (pkg-config lists every module of the contrib build).
OPENCV_PKG := opencv4
OPENCV_MODULES := -lopencv_aruco -lopencv_calib3d -lopencv_imgproc -lopencv_core
# Ceres Solver ships a CMake config only: its headers need Eigen's include path.
LIBS_NOPC := -lembree3 -lmrcal -lceres -lglog -lstdc++
CERES_CFLAGS := -I/usr/include/eigen3

ifeq ($(filter clean distclean,$(MAKECMDGOALS)),)
include $(BUILD)/config.mk
endif

$(BUILD)/config.mk: Makefile scripts/install-deps
	@mkdir -p $(@D)
	@scripts/install-deps
	@{ echo "PKG_CFLAGS := $$(pkg-config --cflags $(PKGS))"; \
	   echo "PKG_LIBS := $$(pkg-config --libs $(PKGS))"; \
	   echo "TEST_PKG_CFLAGS := $$(pkg-config --cflags $(TEST_PKGS))"; \
	   echo "TEST_PKG_LIBS := $$(pkg-config --libs $(TEST_PKGS))"; \
	   echo "OPENCV_CFLAGS := $$(pkg-config --cflags $(OPENCV_PKG))"; \
	   echo "OPENCV_LIBS := $$(pkg-config --libs-only-L $(OPENCV_PKG)) $(OPENCV_MODULES)"; } > $@.tmp && mv $@.tmp $@

WARN := -Wall -Wextra -Wshadow -Wno-unused-parameter
ifeq ($(WERROR),1)
WARN += -Werror
endif
OPT ?= -O2 -g
CFLAGS_ALL   = -std=gnu11 $(OPT) $(WARN) -pthread -MMD -MP -I. $(PKG_CFLAGS) $(EXTRA_CFLAGS)
CXXFLAGS_ALL = -std=c++17 $(OPT) $(WARN) -pthread -MMD -MP -I. $(CERES_CFLAGS) $(EXTRA_CFLAGS)
LDFLAGS_ALL  = -pthread $(EXTRA_LDFLAGS)
LDLIBS_ALL   = $(PKG_LIBS) $(OPENCV_LIBS) $(LIBS_NOPC) -lm

# ---- sources (explicit lists) ---------------------------------------------
# One file a line, by layer (model -> rig -> calib -> fit; README: Architecture).
# One block per subsystem (a folder), so each folder's files are listed together.
MODEL_BASE_SRC := \
    model/base/util.c \
    model/base/notice.c \
    model/base/run.c \
    model/base/paths.c \
    model/base/ini.c \
    model/base/opts.c \
    model/base/report.c
MODEL_IMAGE_SRC := \
    model/image/write.c \
    model/image/read.c
MODEL_SCENE_SRC := \
    model/scene/scene.c \
    model/scene/lex.c \
    model/scene/d3d.c \
    model/scene/obj.c \
    model/scene/load.c \
    model/scene/transform.c \
    model/scene/mesh.c \
    model/scene/workpiece.c
MODEL_BRDF_SRC := \
    model/brdf/brdf.c \
    model/brdf/batch.c \
    model/brdf/table.c \
    model/brdf/rgl.c \
    model/brdf/gen.c
MODEL_RENDER_SRC := \
    model/render/trace.c \
    model/render/shade.c \
    model/render/file.c
MODEL_EDGES_SRC := \
    model/edges/edges.c \
    model/edges/profile.c \
    model/edges/file.c
MODEL_SRC := $(MODEL_BASE_SRC) $(MODEL_IMAGE_SRC) $(MODEL_SCENE_SRC) $(MODEL_BRDF_SRC) $(MODEL_RENDER_SRC) \
    $(MODEL_EDGES_SRC) \
    model/config.c \
    model/camera.c \
    model/cameramodel.c \
    model/sensor.c \
    model/cmd.c \
    model/cmd_brdf.c
MODEL_CXX_SRC := model/base/lsq.cc

RIG_TURNTABLE_SRC := \
    rig/turntable/turntable.c \
    rig/turntable/apt.c \
    rig/turntable/sim.c
RIG_LAMPS_SRC := \
    rig/lamps/lamps.c \
    rig/lamps/state.c \
    rig/lamps/gpiod.c \
    rig/lamps/sim.c
RIG_CAMERA_SRC := \
    rig/camera/camera.c \
    rig/camera/aravis.c \
    rig/camera/pixfmt.c
RIG_SESSION_SRC := \
    rig/session/plan.c \
    rig/session/plan_views.c \
    rig/session/operator.c \
    rig/session/journal.c \
    rig/session/reader.c \
    rig/session/capture.c \
    rig/session/facts.c \
    rig/session/motion.c \
    rig/session/progress.c \
    rig/session/resume.c \
    rig/session/steps.c \
    rig/session/writer.c
RIG_VIRTUAL_SRC := \
    rig/virtual/truth.c \
    rig/virtual/truth_figures.c \
    rig/virtual/truth_rig.c \
    rig/virtual/truth_samples.c \
    rig/virtual/virtual.c \
    rig/virtual/render.c \
    rig/virtual/texture.c \
    rig/virtual/prerender.c \
    rig/virtual/pose.c \
    rig/virtual/gv_camera.c \
    rig/virtual/gv_render.c \
    rig/virtual/gv_stream.c \
    rig/virtual/gv_xml.c \
    rig/virtual/lamps.c \
    rig/virtual/optics.c \
    rig/virtual/materials.c \
    rig/virtual/place.c
RIG_SRC := $(RIG_TURNTABLE_SRC) $(RIG_LAMPS_SRC) $(RIG_CAMERA_SRC) $(RIG_SESSION_SRC) $(RIG_VIRTUAL_SRC) \
    rig/error.c \
    rig/config.c \
    rig/lab.c \
    rig/lab_day.c \
    rig/cmd_rig.c \
    rig/cmd_capture.c \
    rig/cmd_lab.c

CALIB_GEOMETRY_SRC := \
    calib/geometry/geometry.c \
    calib/geometry/views.c \
    calib/geometry/capture.c \
    calib/geometry/corners.c \
    calib/geometry/mrcal.c \
    calib/geometry/axis.c \
    calib/geometry/refine.c \
    calib/geometry/frame.c \
    calib/geometry/missing.c \
    calib/geometry/output.c \
    calib/geometry/report.c \
    calib/geometry/diff.c \
    calib/geometry/psf.c \
    calib/geometry/export.c \
    calib/geometry/plan.c
CALIB_LAMPS_SRC := \
    calib/lamps/lamps.c \
    calib/lamps/capture.c \
    calib/lamps/sphere.c \
    calib/lamps/highlight.c \
    calib/lamps/direction.c \
    calib/lamps/rays.c \
    calib/lamps/triangulate.c \
    calib/lamps/bundle.c \
    calib/lamps/joint.c \
    calib/lamps/output.c \
    calib/lamps/report.c \
    calib/lamps/pattern.c \
    calib/lamps/drift.c
CALIB_GAIN_SRC := \
    calib/gain/gain.c \
    calib/gain/frames.c \
    calib/gain/input.c \
    calib/gain/capture.c \
    calib/gain/analyse.c \
    calib/gain/dark.c \
    calib/gain/sweep.c \
    calib/gain/fit.c \
    calib/gain/ptc.c \
    calib/gain/linearity.c \
    calib/gain/linearisation.c \
    calib/gain/maps.c \
    calib/gain/photons.c \
    calib/gain/standard.c \
    calib/gain/nonuniformity.c \
    calib/gain/descriptor.c \
    calib/gain/exchange.c \
    calib/gain/spatial.c \
    calib/gain/defects.c \
    calib/gain/emva.c \
    calib/gain/datasheet.c \
    calib/gain/output.c \
    calib/gain/report.c
CALIB_SRC := $(CALIB_GEOMETRY_SRC) $(CALIB_LAMPS_SRC) $(CALIB_GAIN_SRC) \
    calib/capture.c \
    calib/calset.c \
    calib/observe.c \
    calib/sample_pose.c \
    calib/white.c \
    calib/cmd_calib.c \
    calib/cmd_geometry.c \
    calib/cmd_plan_geometry.c \
    calib/cmd_lamps.c \
    calib/cmd_gain.c
CALIB_CXX_SRC := calib/geometry/board_detect.cc

FIT_BRDF_SRC := \
    fit/brdf/fit.c \
    fit/brdf/sample_set.c \
    fit/brdf/covariance.c \
    fit/brdf/compare.c \
    fit/brdf/samples.c
FIT_MATERIAL_SRC := \
    fit/material/material.c \
    fit/material/report.c \
    fit/material/export.c
FIT_VERIFY_SRC := \
    fit/verify/verify.c \
    fit/verify/views.c \
    fit/verify/interreflection.c \
    fit/verify/residuals.c \
    fit/verify/windows.c \
    fit/verify/points.c \
    fit/verify/covariance.c \
    fit/verify/regions.c \
    fit/verify/result_json.c \
    fit/verify/selfcheck.c \
    fit/verify/footprint.c \
    fit/verify/files.c \
    fit/verify/register.c
FIT_LIGHTPLAN_SRC := \
    fit/lightplan/lightplan.c \
    fit/lightplan/files.c \
    fit/lightplan/capture_plan.c
FIT_EVAL_SRC := \
    fit/eval/lab.c \
    fit/eval/study.c \
    fit/eval/study_results.c \
    fit/eval/study_files.c \
    fit/eval/study_merge.c \
    fit/eval/chain.c
FIT_SRC := $(FIT_BRDF_SRC) $(FIT_MATERIAL_SRC) $(FIT_VERIFY_SRC) $(FIT_LIGHTPLAN_SRC) $(FIT_EVAL_SRC) \
    fit/cmd_chain.c \
    fit/cmd_fit.c \
    fit/cmd_export.c \
    fit/cmd_plan.c \
    fit/cmd_verify.c \
    fit/priors.c
LIB_SRC   := $(MODEL_SRC) $(RIG_SRC) $(CALIB_SRC) $(FIT_SRC)

MAIN_SRC  := fit/main.c
TEST_SRC := \
    tests/harness.c \
    tests/fixtures.c \
    tests/apt_sim.c \
    tests/test_harness.c \
    tests/test_model_base.c \
    tests/test_model_brdf.c \
    tests/test_model_brdf_table.c \
    tests/test_model_brdf_rgl.c \
    tests/test_model_camera.c \
    tests/test_model_truncated.c \
    tests/test_model_cli.c \
    tests/test_model_config.c \
    tests/test_model_corpus.c \
    tests/test_model_edges.c \
    tests/test_model_edge_profile.c \
    tests/test_model_image.c \
    tests/test_model_lsq.c \
    tests/test_model_opts.c \
    tests/test_model_render.c \
    tests/test_model_report.c \
    tests/test_model_scene.c \
    tests/test_model_sensor.c \
    tests/test_model_sphere.c \
    tests/test_rig_camera_aravis.c \
    tests/test_rig_camera_settings.c \
    tests/test_rig_cameras.c \
    tests/test_rig_capture.c \
    tests/test_rig_session_readonly.c \
    tests/test_rig_cli.c \
    tests/test_rig_config.c \
    tests/test_rig_lab.c \
    tests/test_rig_lamps.c \
    tests/test_rig_pixfmt.c \
    tests/test_rig_plan.c \
    tests/test_rig_operator.c \
    tests/test_rig_plan_text.c \
    tests/test_rig_turntable.c \
    tests/test_rig_virtual.c \
    tests/test_rig_virtual_lamps.c \
    tests/test_rig_virtual_materials.c \
    tests/test_rig_virtual_inprocess.c \
    tests/test_rig_virtual_optics.c \
    tests/test_rig_virtual_place.c \
    tests/test_calib_gain.c \
    tests/test_calib_gain_emva.c \
    tests/test_calib_gain_standard.c \
    tests/test_calib_gain_descriptor.c \
    tests/test_calib_white.c \
    tests/test_calib_sample_pose.c \
    tests/test_calib_geometry.c \
    tests/test_calib_boards.c \
    tests/test_calib_boards_photo.c \
    tests/test_calib_psf.c \
    tests/test_calib_lamps.c \
    tests/test_calib_plan_geometry.c \
    tests/test_calib_export.c \
    tests/test_fit_brdf.c \
    tests/test_fit_chain.c \
    tests/test_fit_export.c \
    tests/test_fit_lightplan.c \
    tests/test_fit_material.c \
    tests/test_fit_material_stats.c \
    tests/test_fit_verify.c \
    tests/test_fit_verify_study.c \
    tests/test_fit_study_slurm.c \
    tests/test_fit_verify_register.c \
    tests/test_fit_verify_footprint.c \
    tests/test_fit_verify_speed.c
# the tests' photographed-looking boards (OpenCV's blur and JPEG; refl-tests links opencv_imgcodecs)
TEST_CXX_SRC := tests/photo_degrade.cc
BENCH_SRC := tests/bench.c
FUZZ_SRC  := tests/fuzz_parsers.c calib/gain/descriptor.c

obj = $(patsubst %.c,$(BUILD)/%.o,$(1))
LIB_OBJ   := $(call obj,$(LIB_SRC)) $(patsubst %.cc,$(BUILD)/%.o,$(MODEL_CXX_SRC) $(CALIB_CXX_SRC))
LIB       := $(BUILD)/librefl.a

.PHONY: all check check-long demo study bench asan fuzz fuzz-cameramodel man install uninstall clean
all: $(BIN)/refl

$(BUILD)/%.o: %.c | $(BUILD)/config.mk
	@mkdir -p $(@D)
	$(CC) $(CFLAGS_ALL) -c $< -o $@

$(BUILD)/%.o: %.cc | $(BUILD)/config.mk
	@mkdir -p $(@D)
	$(CXX) $(CXXFLAGS_ALL) -c $< -o $@

$(LIB): $(LIB_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BIN)/refl: $(call obj,$(MAIN_SRC)) $(LIB)
	@mkdir -p $(@D)
	$(CC) $(LDFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BIN)/refl-tests: $(call obj,$(TEST_SRC)) $(patsubst %.cc,$(BUILD)/%.o,$(TEST_CXX_SRC)) $(LIB)
	@mkdir -p $(@D)
	$(CC) $(LDFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BUILD)/tests/apt_sim.o: CFLAGS_ALL += $(TEST_PKG_CFLAGS)
$(BUILD)/calib/geometry/board_detect.o: CXXFLAGS_ALL += $(OPENCV_CFLAGS)
# model_brdf_eval_n's GGX loop vectorises (sqrt and selects; model/brdf/batch.c)
$(BUILD)/model/brdf/batch.o: CFLAGS_ALL += -ftree-loop-vectorize -fvect-cost-model=dynamic -fno-math-errno -fno-trapping-math
$(BUILD)/model/sensor.o: CFLAGS_ALL += -ftree-loop-vectorize -fvect-cost-model=dynamic -fno-math-errno -fno-trapping-math -ffp-contract=off
$(BIN)/refl-tests: LDLIBS_ALL += $(TEST_PKG_LIBS) -lopencv_imgcodecs
$(BUILD)/tests/photo_degrade.o: CXXFLAGS_ALL += $(OPENCV_CFLAGS)

# Helpers of tests/test_rig_lamps.c: a fake libgpiod v1 for LD_PRELOAD (built
# without sanitizers so it preloads into the asan build too) and a child
# program that holds lamps on until a signal arrives.
FAKE_GPIOD := $(BUILD)/tests/libfake_gpiod.so
ENOSPC_SHIM := $(BUILD)/tests/libenospc.so
LAMP_CHILD := $(BUILD)/tests/lamp_child

$(FAKE_GPIOD): tests/fake_gpiod.c | $(BUILD)/config.mk
	@mkdir -p $(@D)
	$(CC) -std=gnu11 -O2 -g $(WARN) -fPIC -shared $(PKG_CFLAGS) -o $@ $<

# A full disk for LD_PRELOAD (tests/test_rig_capture.c), where no tmpfs can be mounted.
$(ENOSPC_SHIM): tests/enospc_shim.c | $(BUILD)/config.mk
	@mkdir -p $(@D)
	$(CC) -std=gnu11 -O2 -g $(WARN) -fPIC -shared -o $@ $< -ldl

$(LAMP_CHILD): $(call obj,tests/lamp_child.c) $(LIB)
	@mkdir -p $(@D)
	$(CC) $(LDFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BIN)/refl-bench: $(call obj,$(BENCH_SRC)) $(LIB)
	@mkdir -p $(@D)
	$(CC) $(LDFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

TEST_ENV = REFL=$(BIN)/refl REFL_FAKE_GPIOD=$(FAKE_GPIOD) REFL_LAMP_CHILD=$(LAMP_CHILD) REFL_ENOSPC_SHIM=$(ENOSPC_SHIM) \
  REFL_SCRIPTS_DIR=$(CURDIR)/scripts

check: $(BIN)/refl $(BIN)/refl-tests $(FAKE_GPIOD) $(LAMP_CHILD) $(ENOSPC_SHIM)
	scripts/check-layers
	MAKE="$(MAKE) BUILD=$(BUILD) BIN=$(BIN)" scripts/check-install
	$(TEST_ENV) REFL_TEST_SET=short $(BIN)/refl-tests

# the TEST_LONG tests (tests/test.h): each a minute or more on the virtual rig (each limited to 20 minutes)
check-long: $(BIN)/refl $(BIN)/refl-tests $(FAKE_GPIOD) $(LAMP_CHILD) $(ENOSPC_SHIM)
	$(TEST_ENV) REFL_TEST_SET=long REFL_TEST_TIMEOUT=$${REFL_TEST_TIMEOUT:-1200} $(BIN)/refl-tests

# the lab day from the example virtual rig's lab file, the path a real lab's day takes (refl demo --lab)
demo: $(BIN)/refl
	rm -rf $(BUILD)/demo/session* $(BUILD)/demo/calib   # a fresh lab day (scripts/demo keeps and resumes sessions)
	scripts/demo $(BIN)/refl $(BUILD)/demo --lab examples/lab-demo.ini

# the verification detection study on the virtual rig, through the calibrations and priors of the lab
# day (make demo runs it first when its calibrations are missing; README: refl verify)
study: $(BIN)/refl
	@test -f $(BUILD)/demo/calib/white/white.json || $(MAKE) demo
	REFL_SCRIPTS_DIR=$(CURDIR)/scripts $(BIN)/refl verify --study -o $(BUILD)/study --cases 200 \
	  --calib $(BUILD)/demo/calib --priors $(BUILD)/demo/priors_plywood.json $(BUILD)/demo/priors_painted_steel.json

bench: $(BIN)/refl $(BIN)/refl-bench
	REFL=$(BIN)/refl $(BIN)/refl-bench

# ASan's own SEGV/BUS/FPE handlers are off: the lamp tests fault on purpose to
# check refl's handler (memory errors are still caught and reported).
asan:
	ASAN_OPTIONS=handle_segv=0:handle_sigbus=0:handle_sigfpe=0 $(MAKE) BUILD=build-asan BIN=build-asan/bin OPT="-O1 -g" \
	  EXTRA_CFLAGS="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined" \
	  EXTRA_LDFLAGS="-fsanitize=address,undefined" check

FUZZ_SECONDS ?= 60
fuzz: | $(BUILD)/config.mk
	@mkdir -p $(BUILD)/fuzz/corpus
	clang -std=gnu11 -O1 -g -I. $(PKG_CFLAGS) -fsanitize=fuzzer,address,undefined \
	  -fno-sanitize-recover=undefined -fno-omit-frame-pointer -o $(BUILD)/fuzz/fuzz_parsers \
	  -DREFL_FUZZ_EXAMPLES_DIR='"$(CURDIR)/examples"' $(FUZZ_SRC) $(MODEL_SRC) $(RIG_SRC) \
	  $(PKG_LIBS) $(LIBS_NOPC) -lm -pthread
	$(BUILD)/fuzz/fuzz_parsers -max_total_time=$(FUZZ_SECONDS) -max_len=4096 -timeout=10 \
	  -print_final_stats=1 -artifact_prefix=$(BUILD)/fuzz/ $(BUILD)/fuzz/corpus tests/corpus

# Seeds: the example camera models and the corpus's 'c' inputs without their selector byte.
fuzz-cameramodel: | $(BUILD)/config.mk
	@mkdir -p $(BUILD)/fuzz/cameramodel-corpus $(BUILD)/fuzz/cameramodel-seeds
	cp examples/*.cameramodel $(BUILD)/fuzz/cameramodel-seeds/
	for f in tests/corpus/*cameramodel*; do tail -c +2 $$f > $(BUILD)/fuzz/cameramodel-seeds/$${f##*/}; done
	clang -std=gnu11 -O1 -g -I. $(PKG_CFLAGS) -fsanitize=fuzzer,address,undefined \
	  -fno-sanitize-recover=undefined -fno-omit-frame-pointer -o $(BUILD)/fuzz/fuzz_cameramodel \
	  tests/fuzz_cameramodel.c $(MODEL_SRC) $(RIG_SRC) $(PKG_LIBS) $(LIBS_NOPC) -lm -pthread
	$(BUILD)/fuzz/fuzz_cameramodel -max_total_time=$(FUZZ_SECONDS) -max_len=16384 -timeout=10 \
	  -print_final_stats=1 -artifact_prefix=$(BUILD)/fuzz/cameramodel- $(BUILD)/fuzz/cameramodel-corpus \
	  $(BUILD)/fuzz/cameramodel-seeds

# ---- manual pages and installation ------------------------------------------
PREFIX  ?= /usr/local
DESTDIR ?=
MAN_DIR := $(BUILD)/man/man1
SHARE   := $(DESTDIR)$(PREFIX)/share/refl

man: $(BIN)/refl
	scripts/make-man $(BIN)/refl $(MAN_DIR)

# refl finds its scripts and examples in PREFIX/share/refl (model_share_path)
install: $(BIN)/refl man
	install -d $(DESTDIR)$(PREFIX)/bin $(SHARE)/scripts $(SHARE)/examples $(DESTDIR)$(PREFIX)/share/man/man1
	install -m 0755 $(BIN)/refl $(DESTDIR)$(PREFIX)/bin/refl
	tar -C scripts --exclude=__pycache__ -cf - . | tar -C $(SHARE)/scripts -xf -
	tar -C examples -cf - . | tar -C $(SHARE)/examples -xf -
	install -m 0644 $(MAN_DIR)/*.1 $(DESTDIR)$(PREFIX)/share/man/man1/

uninstall:
	rm -f $(DESTDIR)$(PREFIX)/bin/refl $(DESTDIR)$(PREFIX)/share/man/man1/refl.1 \
	  $(DESTDIR)$(PREFIX)/share/man/man1/refl-*.1
	rm -rf $(SHARE)

clean:
	rm -rf build build-asan bin

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)

// calib/geometry/board_detect.cc — calibration boards found by OpenCV (4.6, with the
// contrib aruco module) behind the C header calib/geometry/board_detect.h. The only
// file of refl that includes OpenCV; every exception stops here and becomes
// a message (model_error_set).
#include "calib/geometry/board_detect.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "model/model.h"

namespace {

// OpenCV's predefined dictionaries by name (cv::aruco::PREDEFINED_DICTIONARY_NAME).
struct dict_name {
    const char *name;
    cv::aruco::PREDEFINED_DICTIONARY_NAME id;
};
const dict_name dicts[] = {
    { "DICT_4X4_50", cv::aruco::DICT_4X4_50 },       { "DICT_4X4_100", cv::aruco::DICT_4X4_100 },
    { "DICT_4X4_250", cv::aruco::DICT_4X4_250 },     { "DICT_4X4_1000", cv::aruco::DICT_4X4_1000 },
    { "DICT_5X5_50", cv::aruco::DICT_5X5_50 },       { "DICT_5X5_100", cv::aruco::DICT_5X5_100 },
    { "DICT_5X5_250", cv::aruco::DICT_5X5_250 },     { "DICT_5X5_1000", cv::aruco::DICT_5X5_1000 },
    { "DICT_6X6_50", cv::aruco::DICT_6X6_50 },       { "DICT_6X6_100", cv::aruco::DICT_6X6_100 },
    { "DICT_6X6_250", cv::aruco::DICT_6X6_250 },     { "DICT_6X6_1000", cv::aruco::DICT_6X6_1000 },
    { "DICT_7X7_50", cv::aruco::DICT_7X7_50 },       { "DICT_7X7_100", cv::aruco::DICT_7X7_100 },
    { "DICT_7X7_250", cv::aruco::DICT_7X7_250 },     { "DICT_7X7_1000", cv::aruco::DICT_7X7_1000 },
    { "DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL },
    { "DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5 },
    { "DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9 },
    { "DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10 },
    { "DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11 },
};

const dict_name *dict_find(const char *name)
{
    for (const dict_name &d : dicts)
        if (name && !strcmp(d.name, name)) return &d;
    return nullptr;
}

cv::Ptr<cv::aruco::Dictionary> dictionary(const calib_board_t *b)
{
    return cv::aruco::getPredefinedDictionary(dict_find(b->dict)->id);
}

cv::Ptr<cv::aruco::CharucoBoard> charuco_board(const calib_board_t *b)
{
    return cv::aruco::CharucoBoard::create(b->width_n + 1, b->height_n + 1, (float)b->spacing_mm,
                                           (float)b->marker_mm, dictionary(b));
}

// Corners refined by cv::cornerSubPix in a window of half-width frac x their
// spacing in the image (the least distance between two of them), 2..25 px.
void refine(const cv::Mat &img, std::vector<cv::Point2f> &c, double frac)
{
    double spacing_px = INFINITY;
    for (size_t a = 0; a < c.size(); a++)
        for (size_t k = a + 1; k < c.size(); k++) spacing_px = std::min(spacing_px, (double)cv::norm(c[a] - c[k]));
    if (!std::isfinite(spacing_px)) return;
    int win = std::max(2, std::min(25, (int)(spacing_px * frac)));
    cv::cornerSubPix(img, c, cv::Size(win, win), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
}

// The corners as found (the detector's row-major order, W a row) into q, the
// order made right-handed in the image (corner 1 - corner 0 crossed with
// corner W - corner 0 > 0, y down).
void chessboard_order(int W, int H, const std::vector<cv::Point2f> &c, double *q)
{
    double ax = c[1].x - c[0].x, ay = c[1].y - c[0].y, bx = c[W].x - c[0].x, by = c[W].y - c[0].y;
    bool flip = ax * by - ay * bx < 0;
    for (int j = 0; j < H; j++)
        for (int i = 0; i < W; i++) {
            const cv::Point2f &p = c[j * W + (flip ? W - 1 - i : i)];
            q[2 * (j * W + i)] = p.x;
            q[2 * (j * W + i) + 1] = p.y;
        }
}

// The median of n <= 4 numbers (x reordered).
double median4(double *x, int n)
{
    for (int a = 1; a < n; a++)
        for (int b = a; b > 0 && x[b] < x[b - 1]; b--) std::swap(x[b], x[b - 1]);
    return n % 2 ? x[n / 2] : (x[n / 2 - 1] + x[n / 2]) / 2;
}

// Corners that do not sit where their neighbours put them: each corner
// against the parallelograms of its neighbours (q(i, j) = q(i-1, j) +
// q(i, j-1) - q(i-1, j-1) and the other three), the median of those
// predictions more than a quarter of the local spacing away (a corner caught
// by glare or a grid a square off). Returns how many.
int inconsistent_corners(int W, int H, const double *q)
{
    int bad = 0;
    for (int j = 0; j < H; j++)
        for (int i = 0; i < W; i++) {
            double px[4], py[4], sp = INFINITY;
            int n = 0;
            for (int di = -1; di <= 1; di += 2)
                for (int dj = -1; dj <= 1; dj += 2) {
                    int a = i + di, b = j + dj;
                    if (a < 0 || a >= W || b < 0 || b >= H) continue;
                    const double *u = &q[2 * (j * W + a)], *v = &q[2 * (b * W + i)], *d = &q[2 * (b * W + a)];
                    px[n] = u[0] + v[0] - d[0];
                    py[n] = u[1] + v[1] - d[1];
                    sp = std::min(sp, std::min(std::hypot(u[0] - d[0], u[1] - d[1]),
                                               std::hypot(v[0] - d[0], v[1] - d[1])));
                    n++;
                }
            const double *c = &q[2 * (j * W + i)];
            if (n && std::hypot(c[0] - median4(px, n), c[1] - median4(py, n)) > 0.25 * sp) bad++;
        }
    return bad;
}

// One attempt's outcome appended to how->attempts.
void attempt(calib_board_how_t *how, const char *name, const char *outcome)
{
    if (!how) return;
    size_t n = strlen(how->attempts);
    snprintf(how->attempts + n, sizeof how->attempts - n, "%s%s: %s", n ? "; " : "", name, outcome);
}

// The contrast-normalised copy: CLAHE over tiles of about 8 x 8 of the
// board's squares as large as the image allows (a gradient of light or a
// vignette flattened, the squares' contrast kept), clip limit 3.
cv::Mat normalised(const cv::Mat &img, int W, int H)
{
    int tiles = std::max(2, std::min(16, (std::max(W, H) + 1) / 2));
    cv::Ptr<cv::CLAHE> clahe = cv::createCLAHE(3.0, cv::Size(tiles, tiles));
    cv::Mat out;
    clahe->apply(img, out);
    return out;
}

// OpenCV's classic detector (adaptive threshold, normalised image) on src,
// its corners refined by cornerSubPix on img (the image itself) in a window
// of half-width 0.4 x their spacing (2..25 px: the neighbouring corners stay
// outside it). false: not found (its outcome in out).
bool classic(const cv::Mat &img, const cv::Mat &src, int W, int H, std::vector<cv::Point2f> &c, char *out,
             size_t outn)
{
    bool found = cv::findChessboardCorners(src, cv::Size(W, H), c,
                                           cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
    if (!found || (int)c.size() != W * H) {
        snprintf(out, outn, "no %dx%d chessboard (findChessboardCorners, adaptive threshold, normalised)", W, H);
        return false;
    }
    refine(img, c, 0.4);
    snprintf(out, outn, "found, %d corners refined by cornerSubPix", W * H);
    return true;
}

// A detector's whole board into q (ordered) unless some of its corners are
// inconsistent with their neighbours (q all NAN again, out says so); else
// out = found (may be out itself).
bool accept(int W, int H, const std::vector<cv::Point2f> &c, double *q, char *out, size_t outn, const char *found)
{
    chessboard_order(W, H, c, q);
    int bad = inconsistent_corners(W, H, q);
    if (bad) {
        for (int k = 0; k < 2 * W * H; k++) q[k] = NAN;
        snprintf(out, outn, "its %dx%d grid refused: %d corners more than a quarter square from where their "
                 "neighbours put them", W, H, bad);
        return false;
    }
    if (found != out) snprintf(out, outn, "%s", found);
    return true;
}

// Who found the board: the attempt's outcome and the detector's name in how.
int found_by(calib_board_how_t *how, const char *name, const char *out, int n)
{
    attempt(how, name, out);
    if (how) snprintf(how->detector, sizeof how->detector, "%s", name);
    return n;
}

// A chessboard whole: the detectors of mask in turn until one finds it.
int detect_chessboard(const calib_board_t *b, const cv::Mat &img, double *q, unsigned mask, calib_board_how_t *how)
{
    const int W = b->width_n, H = b->height_n;
    std::vector<cv::Point2f> c;
    char out[200];
    if (mask & CALIB_BOARD_DET_SB) {
        // NORMALIZE_IMAGE (equalizeHist) loses a board on a dark background; EXHAUSTIVE only when the quick
        // search fails. Its corners are sub-pixel already (0.03 px on tests/test_calib_boards.c's synthetic
        // image; cornerSubPix after it made them worse on the virtual rig's frames, whose edges are sampled at
        // pixel centres).
        bool found = cv::findChessboardCornersSB(img, cv::Size(W, H), c, 0) ||
                     cv::findChessboardCornersSB(img, cv::Size(W, H), c, cv::CALIB_CB_EXHAUSTIVE);
        if (!found || (int)c.size() != W * H)
            snprintf(out, sizeof out, "no %dx%d chessboard (findChessboardCornersSB, the whole board needed)", W, H);
        else if (accept(W, H, c, q, out, sizeof out, "found"))
            return found_by(how, "opencv-sb", out, W * H);
        attempt(how, "opencv-sb", out);
    }
    if (mask & CALIB_BOARD_DET_CLASSIC) {
        if (classic(img, img, W, H, c, out, sizeof out) && accept(W, H, c, q, out, sizeof out, out))
            return found_by(how, "opencv-classic", out, W * H);
        attempt(how, "opencv-classic", out);
    }
    if (mask & CALIB_BOARD_DET_CLASSIC_NORMALISED) {
        if (classic(img, normalised(img, W, H), W, H, c, out, sizeof out) && accept(W, H, c, q, out, sizeof out, out))
            return found_by(how, "opencv-classic-normalised", out, W * H);
        attempt(how, "opencv-classic-normalised", out);
    }
    return 0;
}

// A ChArUco board, whole or in part: markers, then the corners between them.
int detect_charuco(const calib_board_t *b, const cv::Mat &img, double *q, calib_board_how_t *how)
{
    cv::Ptr<cv::aruco::CharucoBoard> board = charuco_board(b);
    cv::Ptr<cv::aruco::DetectorParameters> par = cv::aruco::DetectorParameters::create();
    par->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;   // the chessboard corners are refined below
    std::vector<std::vector<cv::Point2f>> mc, rejected;
    std::vector<int> ids;
    cv::aruco::detectMarkers(img, board->dictionary, mc, ids, par, rejected);
    // markers of another dictionary or board (ids beyond this board's) are not ours
    std::vector<std::vector<cv::Point2f>> mk;
    std::vector<int> mid;
    for (size_t k = 0; k < ids.size(); k++)
        if (ids[k] >= 0 && ids[k] < calib_board_charuco_markers(b)) {
            mk.push_back(mc[k]);
            mid.push_back(ids[k]);
        }
    if (mid.empty()) {
        char t[160];
        snprintf(t, sizeof t, "no ArUco marker of %s (ids 0..%d) found", b->dict, calib_board_charuco_markers(b) - 1);
        attempt(how, "opencv-charuco", t);
        return 0;
    }
    std::vector<cv::Point2f> cc;
    std::vector<int> cid;
    cv::aruco::interpolateCornersCharuco(mk, mid, img, board, cc, cid, cv::noArray(), cv::noArray(), 2);
    if (cc.empty()) {
        char t[160];
        snprintf(t, sizeof t, "%zu ArUco markers of %s found, but no chessboard corner between two of them",
                 mid.size(), b->dict);
        attempt(how, "opencv-charuco", t);
        return 0;
    }
    // the interpolated corners refined in a window that stays off the markers' corners: half-width half the
    // gap between a marker and its square's edge (interpolateCornersCharuco's own refinement left them 0.7 px
    // RMS off on synthetic images of 36 px squares, this 0.04 px)
    refine(img, cc, 0.5 * (1 - b->marker_mm / b->spacing_mm));
    int n = 0;
    for (size_t k = 0; k < cc.size(); k++) {
        int id = cid[k];
        if (id < 0 || id >= b->width_n * b->height_n) continue;
        if (!(cc[k].x >= 0 && cc[k].y >= 0 && cc[k].x <= img.cols - 1 && cc[k].y <= img.rows - 1)) continue;
        q[2 * id] = cc[k].x;
        q[2 * id + 1] = cc[k].y;
        n++;
    }
    char t[96];
    snprintf(t, sizeof t, "%d corners found between %zu markers", n, mid.size());
    attempt(how, "opencv-charuco", t);
    if (how && n) snprintf(how->detector, sizeof how->detector, "opencv-charuco");
    return n;
}

// The print at a board point (the header's frame): 0 black, 255 white.
struct pattern {
    const calib_board_t *b;
    std::vector<int> marker;            // per square (I, J): the marker's index, -1 none
    std::vector<cv::Mat> bits;          // per marker: its modules (n x n, 0 / 255)
    std::vector<cv::Rect2d> box;        // per marker: its square in the header's frame (mm)

    explicit pattern(const calib_board_t *bb) : b(bb)
    {
        int sx = b->width_n + 1, sy = b->height_n + 1;
        marker.assign((size_t)sx * sy, -1);
        if (b->kind != CALIB_BOARD_CHARUCO) return;
        cv::Ptr<cv::aruco::CharucoBoard> board = charuco_board(b);
        int n = board->dictionary->markerSize + 2;
        for (size_t k = 0; k < board->objPoints.size(); k++) {
            const std::vector<cv::Point3f> &c = board->objPoints[k];
            double x0 = std::min(c[0].x, c[2].x) - b->spacing_mm, y0 = std::min(c[0].y, c[2].y) - b->spacing_mm;
            double x1 = std::max(c[0].x, c[2].x) - b->spacing_mm, y1 = std::max(c[0].y, c[2].y) - b->spacing_mm;
            cv::Mat m;
            cv::aruco::drawMarker(board->dictionary, board->ids[k], n, m, 1);
            // corner 0 is the marker image's top-left; its rows run toward corner 3
            if (c[3].y < c[0].y) cv::flip(m, m, 0);
            if (c[1].x < c[0].x) cv::flip(m, m, 1);
            int I = (int)std::floor((x0 + x1) / 2 / b->spacing_mm) + 1, J = (int)std::floor((y0 + y1) / 2 / b->spacing_mm) + 1;
            if (I < 0 || J < 0 || I >= sx || J >= sy) continue;
            marker[(size_t)J * sx + I] = (int)bits.size();
            bits.push_back(m);
            box.emplace_back(x0, y0, x1 - x0, y1 - y0);
        }
    }

    int at(double x, double y) const
    {
        int sx = b->width_n + 1, sy = b->height_n + 1;
        int I = (int)std::floor(x / b->spacing_mm) + 1, J = (int)std::floor(y / b->spacing_mm) + 1;
        if (I < 0 || J < 0 || I >= sx || J >= sy) return 255;    // the quiet zone
        int k = marker[(size_t)J * sx + I];
        if (k < 0) return (I + J) % 2 == 0 ? 0 : 255;
        const cv::Rect2d &r = box[k];
        if (x < r.x || y < r.y || x >= r.x + r.width || y >= r.y + r.height) return 255;
        const cv::Mat &m = bits[k];
        int col = std::min(m.cols - 1, (int)((x - r.x) / r.width * m.cols));
        int row = std::min(m.rows - 1, (int)((y - r.y) / r.height * m.rows));
        return m.at<unsigned char>(row, col) > 127 ? 255 : 0;
    }
};

}   // namespace

extern "C" {

const char *calib_board_kind_name(calib_board_kind_t kind)
{
    return kind == CALIB_BOARD_CHARUCO ? "charuco" : "chessboard";
}

bool calib_board_kind_parse(const char *word, calib_board_kind_t *kind)
{
    if (!word) return false;
    if (!strcmp(word, "chessboard")) *kind = CALIB_BOARD_CHESSBOARD;
    else if (!strcmp(word, "charuco")) *kind = CALIB_BOARD_CHARUCO;
    else return false;
    return true;
}

int calib_board_dict_size(const char *name)
{
    const dict_name *d = dict_find(name);
    if (!d) return 0;
    try {
        return cv::aruco::getPredefinedDictionary(d->id)->bytesList.rows;
    } catch (...) {
        return 0;
    }
}

int calib_board_charuco_markers(const calib_board_t *b)
{
    return (b->width_n + 1) * (b->height_n + 1) / 2;
}

bool calib_board_check(const calib_board_t *b)
{
    if (b->width_n < 2 || b->height_n < 2 || b->width_n > 1000 || b->height_n > 1000) {
        model_error_set(nullptr, 0, "a board of %d x %d inner corners: give --object-width-n and --object-height-n "
                        "2..1000", b->width_n, b->height_n);
        return false;
    }
    if (!(b->spacing_mm > 0) || !std::isfinite(b->spacing_mm)) {
        model_error_set(nullptr, 0, "corner spacing %g mm: give --square-mm > 0", b->spacing_mm);
        return false;
    }
    if (b->kind != CALIB_BOARD_CHARUCO) return true;
    if (!(b->marker_mm > 0 && b->marker_mm < b->spacing_mm)) {
        model_error_set(nullptr, 0, "--charuco-marker-mm %g: a ChArUco marker fits inside its square: give a side "
                        "above 0 and below --square-mm (%g)", b->marker_mm, b->spacing_mm);
        return false;
    }
    int have = calib_board_dict_size(b->dict), need = calib_board_charuco_markers(b);
    if (!have) {
        model_error_set(nullptr, 0, "--charuco-dict %s: not one of OpenCV's predefined dictionaries (DICT_4X4_50 .. "
                        "DICT_7X7_1000, DICT_ARUCO_ORIGINAL, DICT_APRILTAG_16h5 .. DICT_APRILTAG_36h11)", b->dict);
        return false;
    }
    if (have < need) {
        model_error_set(nullptr, 0, "--charuco-dict %s has %d markers, a ChArUco board of %d x %d inner corners "
                        "needs %d: give the board's dictionary (a larger one, e.g. DICT_4X4_250)", b->dict, have,
                        b->width_n, b->height_n, need);
        return false;
    }
    return true;
}

int calib_board_detect_how(const calib_board_t *b, const unsigned char *img, int w, int h, double *q,
                           unsigned mask, calib_board_how_t *how)
{
    if (!calib_board_check(b)) return -1;
    for (int k = 0; k < 2 * b->width_n * b->height_n; k++) q[k] = NAN;
    if (how) how->detector[0] = how->attempts[0] = 0;
    try {
        cv::Mat m(h, w, CV_8UC1, const_cast<unsigned char *>(img));
        return b->kind == CALIB_BOARD_CHARUCO ? detect_charuco(b, m, q, how) : detect_chessboard(b, m, q, mask, how);
    } catch (const std::exception &e) {
        model_error_set(nullptr, 0, "OpenCV failed on a %dx%d image: %s", w, h, e.what());
        return -1;
    }
}

int calib_board_detect(const calib_board_t *b, const unsigned char *img, int w, int h, double *q, char *why,
                       size_t whyn)
{
    calib_board_how_t how;
    int n = calib_board_detect_how(b, img, w, h, q, CALIB_BOARD_DET_ALL, &how);
    if (why && whyn) snprintf(why, whyn, "%s", n == 0 ? how.attempts : "");
    return n;
}

bool calib_board_render(const calib_board_t *b, const double H[9], int w, int h, int ss, unsigned char *img)
{
    if (!calib_board_check(b)) return false;
    try {
        pattern p(b);
        cv::Matx33d Hm(H), Hi = Hm.inv();
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double sum = 0;
                for (int sy = 0; sy < ss; sy++)
                    for (int sx = 0; sx < ss; sx++) {
                        cv::Vec3d u(x - 0.5 + (sx + 0.5) / ss, y - 0.5 + (sy + 0.5) / ss, 1), v = Hi * u;
                        sum += v[2] > 0 ? p.at(v[0] / v[2], v[1] / v[2]) : 128;
                    }
                img[(size_t)y * w + x] = (unsigned char)std::lround(sum / (ss * ss));
            }
        return true;
    } catch (const std::exception &e) {
        model_error_set(nullptr, 0, "rendering the board: %s", e.what());
        return false;
    }
}

}   // extern "C"

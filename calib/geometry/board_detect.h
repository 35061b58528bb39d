// calib/geometry/board_detect.h — calibration boards (chessboards of W x H inner
// corners and ChArUco boards) and their detection by OpenCV (calib/
// board_detect.cc: OpenCV's C++ API behind this C header, as model/base/lsq.cc
// wraps Ceres). `refl calib geometry` uses it for every board mrgingham cannot
// find (non-square chessboards, ChArUco boards, --detector opencv).
//
// The board frame (mrcal's, of its ref_calibration_object): corner (i, j),
// i = 0..width_n-1 along the board's x, j = 0..height_n-1 along its y, is at
// (i, j) spacing_mm, z = 0; corners are listed row by row, corner (i, j) at
// index j width_n + i (mrcal's corners.vnl order).
// - chessboard: (width_n + 1) x (height_n + 1) squares, the square holding
//   the board point (-spacing/2, -spacing/2) black. Found whole or not at all,
//   by OpenCV's detectors in turn until one finds it (calib_board_detect_how):
//   "opencv-sb" cv::findChessboardCornersSB (sub-pixel corners of its own);
//   "opencv-classic" cv::findChessboardCorners (CALIB_CB_ADAPTIVE_THRESH |
//   CALIB_CB_NORMALIZE_IMAGE) then cv::cornerSubPix on the image;
//   "opencv-classic-normalised" the same on a contrast-normalised copy
//   (cv::CLAHE, tiles of about 8 squares), the corners refined on the image
//   itself. A detector's grid with a corner more than a quarter of a square
//   from where its neighbours put it (the median of the parallelograms they
//   span) is refused and the next detector tried. Each orders the corners as
//   the next sentence says: the order comes out with the board's x
//   along the image rows' direction as seen (corner 1 - corner 0 crossed with
//   corner W - corner 0 points into the image: +z away from the camera), up
//   to a half turn (a square board: up to a quarter turn), which the caller
//   resolves (the poses across turntable angles: calib/geometry/geometry.c).
// - charuco: OpenCV's ChArUco board (contrib aruco 4.6,
//   cv::aruco::CharucoBoard::create(width_n + 1, height_n + 1, spacing_mm,
//   marker_mm, dictionary)): its chessboard corner id k is corner index k
//   (i = k mod width_n, j = k / width_n), at OpenCV's board point
//   ((i + 1) s, (j + 1) s); the board frame here is OpenCV's moved by
//   (-s, -s). Markers are decoded (cv::aruco::detectMarkers) and the corners
//   between them interpolated (cv::aruco::interpolateCornersCharuco), so a
//   board partly out of the image or occluded gives the corners it shows; no
//   order ambiguity.
// Pixels: (0, 0) is the centre of the top-left pixel (OpenCV's and mrcal's).
// Errors: -1 / false with the message kept by model_error_set.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum { CALIB_BOARD_CHESSBOARD = 0, CALIB_BOARD_CHARUCO = 1 } calib_board_kind_t;

typedef struct {
    calib_board_kind_t kind;
    int    width_n, height_n;   // inner corners along the board's x and y (>= 2)
    double spacing_mm;          // corner spacing (a square's side)
    double marker_mm;           // charuco: a marker's side (0 < marker_mm < spacing_mm)
    char   dict[32];            // charuco: OpenCV's predefined dictionary, e.g. "DICT_4X4_50"
} calib_board_t;

#define CALIB_BOARD_DEFAULT_DICT "DICT_4X4_50"
// The default marker side as a fraction of the square's (--charuco-marker-mm).
#define CALIB_BOARD_DEFAULT_MARKER_RATIO 0.75

// "chessboard" / "charuco"; parse: false for another word.
const char *calib_board_kind_name(calib_board_kind_t kind);
bool calib_board_kind_parse(const char *word, calib_board_kind_t *kind);
// Markers in OpenCV's predefined dictionary of that name (DICT_4X4_50 ...
// DICT_APRILTAG_36h11); 0 when there is no such dictionary.
int calib_board_dict_size(const char *name);
// The markers a ChArUco board needs: one in every white square,
// ((width_n + 1) (height_n + 1)) / 2.
int calib_board_charuco_markers(const calib_board_t *b);
// The description is usable (sizes, spacing, marker and dictionary). false +
// message naming the option to change.
bool calib_board_check(const calib_board_t *b);

// The board's corners in an 8-bit grey image of w x h pixels (rows
// contiguous): q[2 k], q[2 k + 1] the corner of index k (see above), NAN where
// it was not seen. Returns the number of corners found (0: no board; why, may
// be NULL, then says why), -1 on an error (message).
int calib_board_detect(const calib_board_t *b, const unsigned char *img, int w, int h, double *q, char *why,
                       size_t whyn);

// The chessboard's detectors (a mask; ChArUco boards have one detector).
enum {
    CALIB_BOARD_DET_SB = 1,                // "opencv-sb"
    CALIB_BOARD_DET_CLASSIC = 2,           // "opencv-classic"
    CALIB_BOARD_DET_CLASSIC_NORMALISED = 4,// "opencv-classic-normalised"
    CALIB_BOARD_DET_ALL = 7,
};
// Who found the board and how each detector tried fared.
typedef struct {
    char detector[32];     // the detector that found it ("opencv-sb", "opencv-classic",
                           // "opencv-classic-normalised", "opencv-charuco"); "" when none did
    char attempts[400];    // each attempt in order, "NAME: outcome", "; " between them
} calib_board_how_t;
// calib_board_detect with the detectors of mask tried in turn (the order
// above) and how it went in *how (may be NULL). calib_board_detect is this
// with every detector, its why the attempts when none found the board.
int calib_board_detect_how(const calib_board_t *b, const unsigned char *img, int w, int h, double *q,
                           unsigned mask, calib_board_how_t *how);

// A synthetic image of the board (tests, a board to print): pixel (x, y)
// (w x h, rows contiguous) is the mean of ss x ss samples over the pixel's
// square, each the board's print (black 0, white 255) at the board point
// H^-1 (x, y, 1) (H_px_board: 3 x 3 row-major, board mm -> homogeneous pixel;
// a point outside the board's squares and markers is white, a sample whose
// board point is behind, background 128). false + message.
bool calib_board_render(const calib_board_t *b, const double H_px_board[9], int w, int h, int ss,
                        unsigned char *img);

#ifdef __cplusplus
}
#endif

// model/scene/scene.h — scenes: faces and spheres from D3D, OBJ, STL and PLY
// files, their checks and rigid moves, and the reference workpiece
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/base/base.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Scenes (model/scene/scene.c)
//
// D3D (Ammeraal 1988, the thesis's format):
//     # comment
//     1  0 0 0          numbered vertices: number x y z (mm)
//     2  100 0 0
//     ...
//     Faces:
//     @material steel   sets the material of the faces that follow
//     1 2 3 4.          a face: its vertex numbers, ended by '.'
//                       (may span lines; counter-clockwise seen from outside)
//     @sphere cx cy cz r  extension: an exact sphere (centre, radius in mm,
//                       r > 0) of the current material, on a line of its own
//                       after 'Faces:'. A D3D file needs at least one face or
//                       sphere. OBJ has no spheres.
// Wavefront OBJ: v, f (v, v/vt, v/vt/vn, v//vn, negative indices), usemtl;
// vn, vt, o, g, s, mtllib, l are ignored; other statements are errors.
// Faces without a material get the material "default".
// STL (binary or ASCII; model/scene/mesh.c): triangles, their repeated
// corners merged into shared vertices (equal bit for bit), facet normals
// ignored (the corner order gives the normal); every face "default".
// PLY (ascii or binary_little_endian): element vertex (x, y, z; other
// properties skipped), element face (list vertex_indices or vertex_index,
// 0-based; polygons checked for planarity like the others), other elements
// skipped; every face "default". Errors name the line (ASCII) or the byte
// offset (binary); faces of a binary file have line 0.
// Units: the coordinates are in mm unless unit_mm says otherwise
// (model_units_parse: --units mm, m or in); a D3D/OBJ/STL/PLY scene's
// spheres and vertices are scaled alike.

typedef struct {
    int          nverts;
    const int   *verts;      // indices into scene->vertices (0-based)
    int          material;   // index into scene->material_names
    model_vec3_t normal;     // unit normal (Newell), right-hand rule on vertex order
    double       offset_mm;  // plane: normal . x = offset_mm
    int          line;       // line of the face in the source file
    int          number;     // 1-based face number in the file (for messages)
} model_face_t;

typedef struct {
    model_vec3_t centre_mm;  // world frame
    double       radius_mm;  // > 0
    int          material;   // index into scene->material_names
    int          line;       // line of the @sphere in the source file
} model_sphere_t;

typedef struct {
    int            nvertices;
    model_vec3_t  *vertices;     // mm, world frame
    int            nfaces;
    model_face_t  *faces;
    int            nmaterials;
    char         **material_names;
    char          *path;         // as given
    char           sha256[65];   // of the file contents
    int           *vert_storage_; // private
    int            nspheres;     // exact spheres (D3D @sphere); 0 for OBJ
    model_sphere_t *spheres;     // sphere k is "face" nfaces + k in pixel_info
    char           warning[320]; // model_scene_load: a warning it gave ("" none), e.g. the units'
} model_scene_t;

typedef struct {
    double planarity_tol_mm;     // max distance of a vertex from its face's plane (default 0.01)
    double unit_mm;              // mm per unit of the file's coordinates; 0: mm, not said (default)
} model_scene_options_t;

// An OBJ, STL or PLY scene whose bounding box is smaller than this on every
// side, loaded with no unit given, gets a warning (metres read as mm?).
#define MODEL_SCENE_SMALL_MM 5.0
// "mm" -> 1, "m" -> 1000, "in" -> 25.4 (mm per unit); false for anything else.
bool model_units_parse(const char *s, double *unit_mm);

#define MODEL_SCENE_OPTIONS_DEFAULT ((model_scene_options_t){ .planarity_tol_mm = 0.01 })

// Load a scene file: STL and PLY told by their content (a .stl name also
// makes a damaged STL read as one, for its error), D3D and OBJ by the name
// (.d3d, .obj, case-insensitive). opt may be NULL. An OBJ/STL/PLY scene under
// MODEL_SCENE_SMALL_MM with opt->unit_mm 0 gets scene->warning, also given
// to model_warning as "PATH: ...".
model_scene_t *model_scene_load(const char *path, const model_scene_options_t *opt);
model_scene_t *model_scene_parse_d3d(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_obj(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_stl(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_ply(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
void           model_scene_free(model_scene_t *scene);
// Index of a material name in the scene, or -1.
int            model_scene_material_index(const model_scene_t *scene, const char *name);
// A deep copy rotated by angle_deg about the world z axis (the turntable);
// sphere centres rotate with the vertices.
model_scene_t *model_scene_rotated_z(const model_scene_t *scene, double angle_deg);
// A deep copy moved rigidly: x' = R x + t (R row-major 3x3, a rotation; t in
// mm); face normals and plane offsets, sphere centres move with the vertices.
model_scene_t *model_scene_transformed(const model_scene_t *scene, const double R[9], const double t[3]);
// The pose of a scene standing on a wedge (the sample fixture of capture
// plans, [sample] tilt_deg / tilt_azimuth_deg): R = rotation by tilt_deg about
// the horizontal hinge axis (cos az, sin az, 0) through the origin
// (right-handed), t = (0, 0, lift) with lift = the scene's lowest z minus the
// rotated scene's lowest z (its lowest point stays at its height). Apply with
// model_scene_transformed; the turntable angle applies after.
void model_scene_wedge_pose(const model_scene_t *scene, double tilt_deg, double tilt_azimuth_deg, double R[9],
                            double t[3]);

// ---------------------------------------------------------------------------
// The reference workpiece (model/scene/workpiece.c; thesis ch. 6): a base plate
// with a welded stiffener, and the wrong descriptions verification is tested
// with. Plate: x -px/2..px/2, y -py/2..py/2, z 0..pz. Stiffener along y,
// centred on the plate, its top at pz + height_mm * height_scale; T: a web of
// web_thickness_mm under a flange flange_width_mm x flange_thickness_mm; I: a
// flat bar of web_thickness_mm; none: the plate alone. The stiffener is then
// rotated by rotate_deg about z through its centre and shifted by shift_mm
// (x, y). The defaults make examples/t_stiffener.d3d.

typedef enum { MODEL_STIFFENER_T, MODEL_STIFFENER_I, MODEL_STIFFENER_NONE } model_stiffener_kind_t;

typedef struct {
    model_stiffener_kind_t kind;
    double plate_mm[3];            // 400 300 10
    double web_thickness_mm;       // 8
    double length_mm;              // 260 (along y)
    double height_mm;              // 88 (above the plate, flange included)
    double flange_width_mm;        // 60
    double flange_thickness_mm;    // 8
    double shift_mm[2];            // 0 0
    double rotate_deg;             // 0
    double height_scale;           // 1
    const char *plate_material;    // "plywood"
    const char *stiffener_material;// "painted_steel"
} model_stiffener_t;

model_stiffener_t model_stiffener_default(void);
const char *model_stiffener_kind_name(model_stiffener_kind_t k);   // "T", "I", "none"
int         model_stiffener_kind_from_name(const char *s);         // -1 if unknown
// The D3D text (caller frees), or NULL with a message for impossible sizes.
char          *model_stiffener_d3d(const model_stiffener_t *p);
model_scene_t *model_stiffener_scene(const model_stiffener_t *p, const char *name);

#ifdef __cplusplus
}
#endif

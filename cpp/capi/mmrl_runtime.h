/* mmrl_runtime.h: the C interface of the mmrl runtime (C99; docs/engines.md).
 *
 * One shared library (libmmrl_runtime_c) and one controller file (mmrl export RUN -o x.mmrl)
 * give any engine a character driven by a trained policy: load the controller, create
 * characters, set their targets or sticks (and obstacles, and requests), call update(dt), read
 * the pose.
 *
 * Conventions
 *   - Every function returns an mmrl_status (MMRL_OK = 0) except the destructors, the version
 *     queries and the error-message getters. No C++ exception and no abort crosses this
 *     boundary: an unexpected failure returns MMRL_ERROR_INTERNAL with its message.
 *   - Errors: mmrl_character_last_error(c) and mmrl_controller_last_error(ctl) give the message
 *     of the last failed call on that handle; mmrl_last_error() gives the message of the last
 *     failed call on the calling thread (the only one for calls that fail before a handle
 *     exists, such as a load). Strings stay valid until the next failing call on the same handle
 *     (or thread), or until the handle is destroyed. "" when there was no error.
 *   - Out-parameters are written only on MMRL_OK.
 *   - Units: meters, radians, seconds, speeds in m/s. World: Y up; the character moves on the
 *     XZ plane; yaw 0 faces +Z, +X is its left (right-handed, as BVH). Quaternions are
 *     (w, x, y, z).
 *
 * Threads
 *   - A loaded controller is immutable: any number of threads may create characters from it
 *     and query it at the same time.
 *   - Each character is independent: calls on different characters may run on different
 *     threads at the same time. Calls on the same character must not overlap (one thread at a
 *     time, or the caller's lock).
 *   - Destroying a controller while characters made from it live is allowed: they keep it
 *     alive; it is freed with the last of them.
 *   - mmrl_last_error() is per thread.
 */
#ifndef MMRL_RUNTIME_H
#define MMRL_RUNTIME_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(_WIN32)
#define MMRL_API __declspec(dllexport)
#else
#define MMRL_API __attribute__((visibility("default")))
#endif

/* The version of this interface: incremented when a function changes or goes. */
#define MMRL_API_VERSION 1

typedef enum mmrl_status {
  MMRL_OK = 0,
  MMRL_ERROR_INVALID_ARGUMENT = 1, /* a NaN target, a negative dt, an unknown tag, ... */
  MMRL_ERROR_FILE = 2,             /* the controller file is missing, truncated or corrupt */
  MMRL_ERROR_VERSION = 3,          /* the file is of another format version */
  MMRL_ERROR_NULL = 4,             /* a NULL handle or pointer where one is needed */
  MMRL_ERROR_BUFFER_TOO_SMALL = 5, /* a caller's buffer holds fewer joints than the skeleton has */
  MMRL_ERROR_INTERNAL = 6          /* anything else (out of memory, ...) */
} mmrl_status;

typedef struct mmrl_controller mmrl_controller;
typedef struct mmrl_character mmrl_character;

/* A character's last decision (one per frames_per_step frames shown). */
typedef struct mmrl_decision {
  int64_t count;         /* decisions so far */
  int64_t frames_before; /* frames shown before it: its time is frames_before / fps */
  int64_t match;         /* the matched database frame (played from match + 1) */
  int32_t transition;    /* 1 when it left the current clip's continuation */
  float root_x, root_z, root_yaw; /* the character frame when it was made */
  float target_x, target_z;       /* the target it was made for (a stick's: the last one set) */
  float cost;                     /* the match's squared distance (normalized features) */
} mmrl_decision;

/* Versions: of this interface (MMRL_API_VERSION of the library built) and of the controller
 * file format it reads. */
MMRL_API int32_t mmrl_api_version(void);
MMRL_API int32_t mmrl_file_version(void);
/* A short name of a status ("MMRL_ERROR_FILE"). */
MMRL_API const char* mmrl_status_name(mmrl_status status);
/* The last failed call's message on this thread ("" if none). */
MMRL_API const char* mmrl_last_error(void);

/* ----------------------------------------------------------------- controllers */
/* Loads and checks a controller file. On failure *out is NULL and the message names the file. */
MMRL_API mmrl_status mmrl_controller_load(const char* path, mmrl_controller** out);
/* The same from `size` bytes in memory (copied; `name` only names them in messages, may be NULL). */
MMRL_API mmrl_status mmrl_controller_load_memory(const void* data, size_t size, const char* name,
                                                 mmrl_controller** out);
/* Releases the caller's reference (NULL is ignored). */
MMRL_API void mmrl_controller_destroy(mmrl_controller* controller);
MMRL_API const char* mmrl_controller_last_error(const mmrl_controller* controller);

MMRL_API mmrl_status mmrl_controller_num_joints(const mmrl_controller* controller, int32_t* out);
/* Joint j's name, NUL-terminated, into `buffer` of `size` bytes (MMRL_ERROR_BUFFER_TOO_SMALL if
 * it does not fit; *needed, if not NULL, gets the bytes it needs, NUL included). */
MMRL_API mmrl_status mmrl_controller_joint_name(const mmrl_controller* controller, int32_t joint, char* buffer,
                                                size_t size, size_t* needed);
/* Joint j's parent index (-1 for the root); parents come before their children. */
MMRL_API mmrl_status mmrl_controller_joint_parent(const mmrl_controller* controller, int32_t joint, int32_t* out);
/* Frames per second of the motion (update shows one frame per 1/fps seconds). */
MMRL_API mmrl_status mmrl_controller_fps(const mmrl_controller* controller, float* out);
/* Frames shown per decision, and the task's success radius (meters). */
MMRL_API mmrl_status mmrl_controller_frames_per_step(const mmrl_controller* controller, int32_t* out);
MMRL_API mmrl_status mmrl_controller_success_radius(const mmrl_controller* controller, float* out);
/* The database frames a character may start on (the valid ones, ascending): how many, and the
 * k-th. */
MMRL_API mmrl_status mmrl_controller_num_start_frames(const mmrl_controller* controller, int64_t* out);
MMRL_API mmrl_status mmrl_controller_start_frame(const mmrl_controller* controller, int64_t k, int64_t* out);
/* Obstacles the controller's task takes (0 for the plane task). */
MMRL_API mmrl_status mmrl_controller_max_obstacles(const mmrl_controller* controller, int32_t* out);

/* ----------------------------------------------------------------- characters */
/* A character at world (x, z) (meters) facing yaw (radians), on database frame start_frame
 * (-1: the first valid frame). Its target starts where it stands. */
MMRL_API mmrl_status mmrl_character_create(mmrl_controller* controller, float x, float z, float yaw,
                                           int64_t start_frame, mmrl_character** out);
MMRL_API void mmrl_character_destroy(mmrl_character* character);
MMRL_API const char* mmrl_character_last_error(const mmrl_character* character);

/* The target (world meters), used from the next decision on; it switches a stick off (the
 * policy decides again). */
MMRL_API mmrl_status mmrl_character_set_target(mmrl_character* character, float x, float z);
/* The facing to arrive with, for a controller whose task reads one (the arrive task): a world
 * yaw in RADIANS (0 faces +Z, positive turns left), used from the next decision on. Such a
 * controller's character refuses to decide until it is set (mmrl_character_update then returns
 * MMRL_ERROR_INVALID_ARGUMENT naming it). A non-finite yaw, or a task without a facing, is
 * MMRL_ERROR_INVALID_ARGUMENT. */
MMRL_API mmrl_status mmrl_character_set_facing(mmrl_character* character, float yaw);
/* A stick in place of the target and the policy, from the next decision on: the player's
 * direction (world x, z; any length > 0, normalized) and speed (m/s, > 0). Each decision then
 * matches the scripted joystick's trajectory (positions d * speed * t at 10, 20 and 30 frames,
 * directions d, d in the character frame) through the task's own search (transition cost,
 * clip costs, request, path filter). mmrl_character_set_target switches it off. A zero or
 * non-finite direction, or a speed that is not finite and > 0, is MMRL_ERROR_INVALID_ARGUMENT
 * (the message names it); the character is then unchanged. */
MMRL_API mmrl_status mmrl_character_set_stick(mmrl_character* character, float x, float z, float speed);
/* Obstacle tasks: n rectangles, centres and half sizes n x 2 (x, z), angles n (radians),
 * velocities n x 2 (m/s) or NULL for standing ones. Read at the next decision. */
MMRL_API mmrl_status mmrl_character_set_obstacles(mmrl_character* character, int32_t n, const float* centres,
                                                  const float* half_sizes, const float* angles,
                                                  const float* velocities);
/* A request over the controller's tags ("style=elderly & gait=walk"; "" or NULL for every clip),
 * from the next decision on. An unknown tag, or a request no clip satisfies, is
 * MMRL_ERROR_INVALID_ARGUMENT with the tags available in the message. */
MMRL_API mmrl_status mmrl_character_set_request(mmrl_character* character, const char* request);

/* Advances dt seconds (0 <= dt <= 60) and writes the pose shown now into the caller's buffers,
 * each of `capacity` joints (at least mmrl_controller_num_joints):
 *   local_rotations     capacity x 4 (w, x, y, z): each joint's rotation in its parent's frame,
 *                       the root's in the world; required
 *   local_translations  capacity x 3 meters (the root's world position, the others' offsets),
 *                       or NULL
 *   root                3 floats: the character frame's world x, z and yaw (facing), or NULL
 * Joint order and names: mmrl_controller_joint_name / _parent. */
MMRL_API mmrl_status mmrl_character_update(mmrl_character* character, float dt, float* local_rotations,
                                           float* local_translations, int32_t capacity, float* root);
/* The database frame shown now and whether the last decision jumped to another clip. */
MMRL_API mmrl_status mmrl_character_frame(const mmrl_character* character, int64_t* frame, int32_t* transition);
/* The character frame now: world x, z and yaw (3 floats). */
MMRL_API mmrl_status mmrl_character_root(const mmrl_character* character, float* root);
/* The last decision (all zero, match -1, before the first). */
MMRL_API mmrl_status mmrl_character_last_decision(const mmrl_character* character, mmrl_decision* out);

#ifdef __cplusplus
}
#endif

#endif /* MMRL_RUNTIME_H */

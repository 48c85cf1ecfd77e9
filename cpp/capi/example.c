/* A C99 program against the installed C interface (the capi_pkg_config test builds it with
 * `pkg-config --cflags --libs mmrl_runtime`): with a controller file it walks one character to a
 * target and prints where it ends; without one it checks the versions and a failing load. */
#include <stdio.h>
#include <string.h>

#include "mmrl_runtime.h"

int main(int argc, char** argv) {
  mmrl_controller* ctl = NULL;
  mmrl_character* ch = NULL;
  float rotations[4 * 256], root[3];
  int32_t joints = 0;
  int frame;
  if (mmrl_api_version() != MMRL_API_VERSION) return 1;
  if (argc < 2) {
    if (mmrl_controller_load("/nonexistent.mmrl", &ctl) != MMRL_ERROR_FILE || ctl != NULL) return 1;
    if (strstr(mmrl_last_error(), "/nonexistent.mmrl") == NULL) return 1;
    printf("api %d, file format %d; a missing file: %s\n", (int)mmrl_api_version(), (int)mmrl_file_version(),
           mmrl_last_error());
    return 0;
  }
  if (mmrl_controller_load(argv[1], &ctl) != MMRL_OK) {
    fprintf(stderr, "%s\n", mmrl_last_error());
    return 2;
  }
  if (mmrl_controller_num_joints(ctl, &joints) != MMRL_OK || joints > 256) return 1;
  if (mmrl_character_create(ctl, 0.0f, 0.0f, 0.0f, -1, &ch) != MMRL_OK) return 1;
  mmrl_character_set_target(ch, 2.0f, 3.0f);
  for (frame = 0; frame < 150; ++frame)
    if (mmrl_character_update(ch, 1.0f / 30.0f, rotations, NULL, 256, root) != MMRL_OK) {
      fprintf(stderr, "%s\n", mmrl_character_last_error(ch));
      return 1;
    }
  printf("root %.3f %.3f %.3f\n", root[0], root[1], root[2]);
  mmrl_character_destroy(ch);
  mmrl_controller_destroy(ctl);
  return 0;
}

// Scene files (config/scenes/*.yaml) → model::Scene. The format is documented in
// config/scenes/README.md; a missing section means the effect is off (ground excepted: a scene
// without `ground:` has none, e.g. free fall). Errors name file, line, key, value and expectation.
#pragma once

#include <numbers>
#include <string>

#include "pedalwave/config/yaml_reader.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::config {

model::Scene load_scene(const std::string& path);
// What the program that loads the scene makes of it: a tool that does not inject faults refuses
// a scene with a `faults:` list (file:line: faults = [list]: expected no faults: list (...)),
// rather than running it as if nothing failed.
struct SceneUse {
  bool faults = true;    // the program injects the scene's faults
  std::string consumer;  // its name, for the message
};
model::Scene load_scene(const std::string& path, const SceneUse& use);
model::Scene parse_scene(const std::string& text, const std::string& name);
model::Scene read_scene(const Reader& r);

// Pieces shared with other configuration files.
// The `robot:` map; link_shape: also its contact geometry (link_shape, link_radius, link_height:
// a scene's keys, refused elsewhere).
model::Params read_robot(const Reader& r, bool link_shape = false);
model::IntegratorOptions read_integrator(const Reader& r);  // the `integrator:` map
// The `gait:` map; A_p in [A_p_min, π]: a scene's amplitude may be negative (a phase shift of
// half a period), the controller's is a magnitude (controller.gait.A_p: A_p_min = 0).
model::GaitParams read_gait(const Reader& r, double A_p_min = -std::numbers::pi);

}  // namespace pedalwave::config

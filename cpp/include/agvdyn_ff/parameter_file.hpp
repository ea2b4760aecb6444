// Parameter and platform files of agvdyn (shared/PLATFORM.md "Files"), read once at start-up.
//
// A parameter file is what `agvdyn identify` writes (agvdyn.platform.write_parameters), YAML or
// JSON: `parameters: {C_l: {value: ..., std: ...}, ...}` and, when known, the vehicle
// `platform: {name, l, b, a, r, i_G}`. Like agvdyn.platform.read_parameters, the flat forms
// `{C_l: {value: ...}, ...}` and `{C_l: 0.33, ...}` are accepted too.
//
// A model beyond the paper (issue 30, agvdyn.model_spec) is a `model:` block
// `{friction: paper|stribeck, delay: SECONDS (or delay_s), com_offset: true|false}` with its extra
// parameters in `parameters` like the 11 (d_sl, d_sr, d_sw, w_sl, w_sr, w_sw with friction stribeck;
// x_c, y_c with com_offset); the Stribeck velocities may instead be the block's
// `stribeck_velocities: [w_sl, w_sr, w_sw]`. Search settings (stribeck_range, delay_range) and the
// delay's std (delay_std_s) are accepted and not used; a delay `auto` is refused (it names a search,
// not a value). Without the block the file is the paper's model and extra parameters are not read.
#pragma once

#include "agvdyn_ff/feedforward.hpp"

#include <string>

namespace agvdyn::ff {

struct ParameterFile {
  Parameters parameters;
  bool has_platform = false;   ///< the file names its vehicle (key `platform`)
  Geometry platform;           ///< that vehicle; the prototype's geometry when has_platform is false
  std::string platform_name;
  bool has_model = false;      ///< the file has a `model:` block
  Extension extension;         ///< its model beyond the paper; the paper's model without the block
};

/// Read a parameter file (YAML or JSON). False with a message naming the file and the key.
bool read_parameter_file(const std::string& path, ParameterFile* out, std::string* error);

/// The same from the text of a file; `source` names it in messages.
bool parse_parameter_file(const std::string& text, const std::string& source, ParameterFile* out,
                          std::string* error);

/// Read a platform file (YAML: l, b, a, r, i_G in SI units, optional name).
bool read_platform_file(const std::string& path, Geometry* out, std::string* name, std::string* error);

}  // namespace agvdyn::ff

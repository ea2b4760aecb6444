#include "agvdyn_ff/parameter_file.hpp"

#include "document.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <vector>

namespace agvdyn::ff {
namespace {

using detail::Node;

bool fail(std::string* error, const std::string& message) {
  if (error != nullptr) *error = message;
  return false;
}

std::string describe(const Node& node) {
  switch (node.kind) {
    case Node::Kind::null: return "null";
    case Node::Kind::scalar: return node.quoted ? "'" + node.text + "'" : node.text;
    case Node::Kind::mapping: return "a mapping";
    case Node::Kind::sequence: return "a list";
  }
  return "?";
}

bool number(const std::string& source, const std::string& key, const Node& node, double* out, std::string* error) {
  if (!node.number(out)) return fail(error, source + ": " + key + "=" + describe(node) + ": expected a number");
  return true;
}

// l, b, a, r, i_G (and name) of a platform mapping; `prefix` is "platform." inside a parameter file.
bool geometry_of(const std::string& source, const std::string& prefix, const Node& node, Geometry* g,
                 std::string* name, std::string* error) {
  static const char* keys[] = {"l", "b", "a", "r", "i_G"};
  if (!node.is_mapping()) {
    return fail(error, source + ": " + (prefix.empty() ? "expected a mapping at the top level"
                                                       : prefix.substr(0, prefix.size() - 1) +
                                                             ": expected a mapping with [l, b, a, r, i_G], found " +
                                                             describe(node)));
  }
  std::vector<std::string> missing;
  for (const char* k : keys) {
    if (node.find(k) == nullptr) missing.push_back(k);
  }
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : ", ") + m;
    return fail(error, source + ": " + (prefix.empty() ? "" : prefix.substr(0, prefix.size() - 1) + ": ") +
                           "missing keys [" + list + "]: a platform needs l, b, a, r, i_G (SI units)");
  }
  double v[5];
  for (int k = 0; k < 5; ++k) {
    if (!number(source, prefix + keys[k], *node.find(keys[k]), &v[k], error)) return false;
  }
  *g = Geometry{v[0], v[1], v[2], v[3], v[4]};
  Model probe;
  if (Model::create(*g, Parameters::paper(), Settings{}, &probe) != Status::ok) {
    return fail(error, source + ": " + (prefix.empty() ? "" : prefix.substr(0, prefix.size() - 1) + ": ") +
                           "geometry l=" + std::to_string(v[0]) + ", b=" + std::to_string(v[1]) + ", a=" +
                           std::to_string(v[2]) + ", r=" + std::to_string(v[3]) + ", i_G=" + std::to_string(v[4]) +
                           ": expected l, b, r, i_G > 0 and |a| < min(l, b)/2");
  }
  if (name != nullptr) {
    const Node* n = node.find("name");
    *name = (n != nullptr && n->kind == Node::Kind::scalar) ? n->text : std::string();
  }
  return true;
}

bool flag(const std::string& source, const std::string& key, const Node& node, bool* out, std::string* error) {
  const std::string& t = node.text;
  if (node.kind == Node::Kind::scalar && !node.quoted && (t == "true" || t == "True" || t == "TRUE")) {
    *out = true;
  } else if (node.kind == Node::Kind::scalar && !node.quoted && (t == "false" || t == "False" || t == "FALSE")) {
    *out = false;
  } else {
    return fail(error, source + ": " + key + "=" + describe(node) + ": expected true or false");
  }
  return true;
}

// The value of parameter `name` in the parameters table (`{value: ...}` or a number); false when missing.
bool parameter_value(const std::string& source, const Node& table, const std::string& name, double* out,
                     std::string* error) {
  const Node& entry = *table.find(name);
  if (entry.is_mapping()) {
    const Node* value = entry.find("value");
    if (value == nullptr) return fail(error, source + ": parameter " + name + " has no 'value'");
    if (!number(source, name + ".value", *value, out, error)) return false;
  } else if (!number(source, name, entry, out, error)) {
    return false;
  }
  if (!std::isfinite(*out)) {
    return fail(error, source + ": parameter " + name + "=" + std::to_string(*out) + ": expected a finite number");
  }
  return true;
}

// friction, delay (delay_s), com_offset and stribeck_velocities of the `model:` block (agvdyn.model_spec);
// `held` names breakaway levels the file gives at the paper's law d_s = d_c (checked, nothing to do).
bool model_block(const std::string& source, const Node& node, Extension* e, std::string* error) {
  static const char* known[] = {"friction", "delay", "delay_s", "delay_std_s", "com_offset", "stribeck_velocities",
                                "stribeck_range", "delay_range", "held"};
  if (!node.is_mapping()) {
    return fail(error, source + ": model: expected a mapping with friction, delay, com_offset, found " + describe(node));
  }
  for (const std::string& key : node.keys) {
    if (std::find(std::begin(known), std::end(known), key) == std::end(known)) {
      return fail(error, source + ": model: unknown key " + key + ": expected some of [com_offset, delay, delay_range, "
                         "delay_s, delay_std_s, friction, held, stribeck_range, stribeck_velocities]");
    }
  }
  if (const Node* h = node.find("held"); h != nullptr && !h->is_null()) {
    const auto level = [](const Node& v) {
      return v.kind == Node::Kind::scalar && (v.text == "d_sl" || v.text == "d_sr" || v.text == "d_sw");
    };
    const Node* bad = !h->is_sequence() ? h : nullptr;
    for (const Node& v : h->values) bad = bad != nullptr || level(v) ? bad : &v;
    if (bad != nullptr) {
      return fail(error, source + ": model.held: " + describe(*bad) + ": expected a list of some of [d_sl, d_sr, d_sw]");
    }
  }
  if (const Node* f = node.find("friction"); f != nullptr) {
    if (f->kind != Node::Kind::scalar || (f->text != "paper" && f->text != "stribeck")) {
      return fail(error, source + ": model.friction=" + describe(*f) + ": expected paper or stribeck");
    }
    e->stribeck = f->text == "stribeck";
  }
  for (const char* key : {"delay", "delay_s"}) {
    const Node* d = node.find(key);
    if (d == nullptr || d->is_null()) continue;
    if (!d->number(&e->delay_s) || !std::isfinite(e->delay_s)) {
      return fail(error, source + ": model." + key + "=" + describe(*d) + ": expected a number of seconds (a "
                         "parameter file gives the delay found, not 'auto')");
    }
  }
  if (const Node* c = node.find("com_offset"); c != nullptr && !flag(source, "model.com_offset", *c, &e->com_offset, error)) {
    return false;
  }
  if (const Node* v = node.find("stribeck_velocities"); v != nullptr && !v->is_null()) {
    if (!v->is_sequence() || v->values.size() != 3) {
      return fail(error, source + ": model.stribeck_velocities=" + describe(*v) + ": expected [w_sl, w_sr, w_sw] in rad/s");
    }
    for (int g = 0; g < 3; ++g) {
      if (!number(source, "model.stribeck_velocities", v->values[static_cast<std::size_t>(g)], &e->w_s[g], error)) {
        return false;
      }
    }
  }
  return true;
}

// The extra parameters the model block asks for, from the parameters table; checked like Model::create.
bool extension_of(const std::string& source, const Node& root, const Node& table, ParameterFile* out,
                  std::string* error) {
  const Node* block = root.find("model");
  if (block == nullptr || block->is_null()) return true;
  Extension e;
  if (!model_block(source, *block, &e, error)) return false;
  std::vector<std::string> needed, missing;
  if (e.stribeck) needed.insert(needed.end(), {"d_sl", "d_sr", "d_sw"});
  const bool listed = block->find("stribeck_velocities") != nullptr && !block->find("stribeck_velocities")->is_null();
  if (e.stribeck && !listed) needed.insert(needed.end(), {"w_sl", "w_sr", "w_sw"});
  if (e.com_offset) needed.insert(needed.end(), {"x_c", "y_c"});
  for (const auto& name : needed) {
    if (table.find(name) == nullptr) missing.push_back(name);
  }
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : ", ") + m;
    return fail(error, source + ": model " + (e.stribeck ? "friction stribeck" : "") +
                           (e.stribeck && e.com_offset ? ", " : "") + (e.com_offset ? "com_offset" : "") +
                           ": missing parameters [" + list + "]");
  }
  double* slots[8] = {&e.d_s[0], &e.d_s[1], &e.d_s[2], &e.w_s[0], &e.w_s[1], &e.w_s[2], &e.x_c, &e.y_c};
  for (int k = 0; k < 8; ++k) {  // the table's w_s before the block's stribeck_velocities
    const std::string name = Extension::names[static_cast<std::size_t>(k)];
    const bool wanted = k < 6 ? e.stribeck : e.com_offset;
    if (wanted && table.find(name) != nullptr && !parameter_value(source, table, name, slots[k], error)) return false;
  }
  for (int g = 0; g < 3 && e.stribeck; ++g) {
    if (!(e.w_s[g] > 0)) {
      return fail(error, source + ": parameter " + std::string(Extension::names[3 + g]) + "=" +
                             std::to_string(e.w_s[g]) + ": expected a Stribeck velocity > 0 rad/s");
    }
  }
  out->has_model = true;
  out->extension = e;
  return true;
}

bool parameters_of(const std::string& source, const Node& root, ParameterFile* out, std::string* error) {
  if (!root.is_mapping()) return fail(error, source + ": expected a mapping at the top level, found " + describe(root));
  const Node* table = root.find("parameters");
  if (table == nullptr) table = &root;
  if (!table->is_mapping()) return fail(error, source + ": 'parameters' must be a mapping of parameter names");
  std::string missing;
  for (const char* name : Parameters::names) {
    if (table->find(name) == nullptr) missing += (missing.empty() ? "" : ", ") + std::string(name);
  }
  if (!missing.empty()) {
    return fail(error, source + ": missing parameters [" + missing +
                           "]: expected all of [C_l, d_vl, d_cl, C_r, d_vr, d_cr, m_ch, C_ch, d_vw, d_cw, B_w]");
  }
  Vector11 p;
  for (int k = 0; k < 11; ++k) {
    if (!parameter_value(source, *table, Parameters::names[k], &p[k], error)) return false;
  }
  ParameterFile result;
  result.parameters = Parameters::from_vector(p);
  if (!extension_of(source, root, *table, &result, error)) return false;
  const Node* platform = root.find("platform");
  if (platform != nullptr && !platform->is_null()) {
    if (!geometry_of(source, "platform.", *platform, &result.platform, &result.platform_name, error)) return false;
    result.has_platform = true;
  }
  *out = result;
  return true;
}

}  // namespace

bool parse_parameter_file(const std::string& text, const std::string& source, ParameterFile* out, std::string* error) {
  Node root;
  std::string message;
  if (!detail::parse_document(text, &root, &message)) return fail(error, source + ": " + message);
  return parameters_of(source, root, out, error);
}

bool read_parameter_file(const std::string& path, ParameterFile* out, std::string* error) {
  Node root;
  if (!detail::read_document(path, &root, error)) return false;
  return parameters_of(path, root, out, error);
}

bool read_platform_file(const std::string& path, Geometry* out, std::string* name, std::string* error) {
  Node root;
  if (!detail::read_document(path, &root, error)) return false;
  return geometry_of(path, "", root, out, name, error);
}

}  // namespace agvdyn::ff

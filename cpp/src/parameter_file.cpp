#include "agvdyn_ff/parameter_file.hpp"

#include "document.hpp"

#include <cmath>
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
    const std::string name = Parameters::names[k];
    const Node& entry = *table->find(name);
    if (entry.is_mapping()) {
      const Node* value = entry.find("value");
      if (value == nullptr) return fail(error, source + ": parameter " + name + " has no 'value'");
      if (!number(source, name + ".value", *value, &p[k], error)) return false;
    } else if (!number(source, name, entry, &p[k], error)) {
      return false;
    }
    if (!std::isfinite(p[k])) {
      return fail(error, source + ": parameter " + name + "=" + std::to_string(p[k]) + ": expected a finite number");
    }
  }
  ParameterFile result;
  result.parameters = Parameters::from_vector(p);
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

// Parameter and platform files as agvdyn writes them (YAML by PyYAML's safe_dump, JSON by json.dumps)
// and the flat forms read_parameters accepts; errors name the file and the key.
#include <agvdyn_ff/parameter_file.hpp>

#include <gtest/gtest.h>

#include <string>

#include "document.hpp"

namespace ff = agvdyn::ff;

namespace {

// What `agvdyn identify --out params.yaml` writes (abridged extras, same shapes).
const char* kIdentifyYaml = R"(parameters:
  C_l:
    value: 0.3342
    unit: kg m^2
    std: 0.0021
    fixed: false
  d_vl:
    value: 4.4649
    unit: N m s/rad
    fixed: false
  d_cl: {value: 12.9458, unit: N m, fixed: false}
  C_r:
    value: 0.4501
    fixed: false
  d_vr:
    value: 2.482
  d_cr:
    value: 17.1071
  m_ch:
    value: 842.0684
  C_ch:
    value: 286.5955
  d_vw:
    value: 0.7316
  d_cw:
    value: 3.9656
  B_w:
    value: 0.121
    unit: kg m^2
    fixed: true
condition_number: 11.56
fixed:
- B_w
platform:
  name: prototype
  l: 1.2
  b: 0.8
  a: 0.05
  r: 0.1
  i_G: 25.0
residual_rms: {}
sources:
- /tmp/ident.parquet
- 'C:\data\run #2.parquet'
settings:
  filter:
    cutoff: 40.0
    order: 4
  segments: null
  note: this is a long plain scalar that PyYAML folds over two lines because it is longer
    than its line width
slip_events:
- t_start: 1.5
  t_end: 1.75
  wheels:
  - fl
  - rl
- t_start: 3.0
  t_end: 3.1
  wheels: [fr]
warning: 'a quoted string: with colon # and hash, folded
  over a line'
)";

const char* kJson = R"({
  "parameters": {
    "C_l": {"value": 0.3342, "unit": "kg m^2", "std": null, "fixed": false},
    "d_vl": {"value": 4.4649}, "d_cl": {"value": 12.9458}, "C_r": {"value": 0.4501},
    "d_vr": {"value": 2.482}, "d_cr": {"value": 17.1071}, "m_ch": {"value": 842.0684},
    "C_ch": {"value": 286.5955}, "d_vw": {"value": 0.7316}, "d_cw": {"value": 3.9656},
    "B_w": {"value": 1.21e-1, "fixed": true}
  },
  "condition_number": null,
  "fixed": ["B_w"],
  "platform": {"name": "small \u00e9", "l": 1.0, "b": 0.7, "a": 0.04, "r": 0.09, "i_G": 20}
})";

void expect_paper(const ff::Parameters& p) {
  const ff::Vector11 ref = ff::Parameters::paper().to_vector();
  EXPECT_TRUE(p.to_vector().isApprox(ref, 1e-15)) << p.to_vector().transpose();
}

}  // namespace

TEST(ParameterFile, ReadsWhatIdentifyWrites) {
  ff::ParameterFile file;
  std::string error;
  ASSERT_TRUE(ff::parse_parameter_file(kIdentifyYaml, "params.yaml", &file, &error)) << error;
  expect_paper(file.parameters);
  ASSERT_TRUE(file.has_platform);
  EXPECT_EQ(file.platform_name, "prototype");
  EXPECT_DOUBLE_EQ(file.platform.l, 1.2);
  EXPECT_DOUBLE_EQ(file.platform.i_G, 25.0);
}

TEST(ParameterFile, ReadsJson) {
  ff::ParameterFile file;
  std::string error;
  ASSERT_TRUE(ff::parse_parameter_file(kJson, "params.json", &file, &error)) << error;
  expect_paper(file.parameters);
  ASSERT_TRUE(file.has_platform);
  EXPECT_EQ(file.platform_name, "small \xc3\xa9");
  EXPECT_DOUBLE_EQ(file.platform.a, 0.04);
}

TEST(ParameterFile, FlatFormsAndNoPlatform) {
  ff::ParameterFile file;
  std::string error;
  const std::string flat =
      "# flat form\nC_l: 0.3342\nd_vl: 4.4649\nd_cl: 12.9458\nC_r: 0.4501\nd_vr: 2.482\nd_cr: 17.1071\n"
      "m_ch: 842.0684\nC_ch: 286.5955\nd_vw: 0.7316\nd_cw: 3.9656\nB_w: {value: 0.121}\n";
  ASSERT_TRUE(ff::parse_parameter_file(flat, "flat.yaml", &file, &error)) << error;
  expect_paper(file.parameters);
  EXPECT_FALSE(file.has_platform);
}

TEST(ParameterFile, ErrorsNameTheFileAndTheKey) {
  ff::ParameterFile file;
  std::string error;
  std::string text = kIdentifyYaml;
  EXPECT_FALSE(ff::parse_parameter_file("parameters:\n  C_l: {value: 1}\n", "p.yaml", &file, &error));
  EXPECT_NE(error.find("p.yaml: missing parameters [d_vl, d_cl"), std::string::npos) << error;
  std::string no_value = text;
  no_value.replace(no_value.find("value: 842.0684"), 15, "val: 842.0684");
  EXPECT_FALSE(ff::parse_parameter_file(no_value, "p.yaml", &file, &error));
  EXPECT_EQ(error, "p.yaml: parameter m_ch has no 'value'");
  std::string word = text;
  word.replace(word.find("0.7316"), 6, "'0.73'");
  EXPECT_FALSE(ff::parse_parameter_file(word, "p.yaml", &file, &error));
  EXPECT_EQ(error, "p.yaml: d_vw.value='0.73': expected a number");
  std::string geometry = text;
  geometry.replace(geometry.find("a: 0.05"), 7, "a: 0.5");
  EXPECT_FALSE(ff::parse_parameter_file(geometry, "p.yaml", &file, &error));
  EXPECT_NE(error.find("p.yaml: platform: geometry"), std::string::npos) << error;
  EXPECT_FALSE(ff::parse_parameter_file("- 1\n- 2\n", "list.yaml", &file, &error));
  EXPECT_NE(error.find("expected a mapping at the top level"), std::string::npos) << error;
  EXPECT_FALSE(ff::parse_parameter_file("{\"C_l\": [1, 2", "bad.json", &file, &error));
  EXPECT_NE(error.find("bad.json: line 1:"), std::string::npos) << error;
  EXPECT_FALSE(ff::read_parameter_file("/nonexistent/params.yaml", &file, &error));
  EXPECT_NE(error.find("/nonexistent/params.yaml: cannot be read"), std::string::npos) << error;
}

TEST(Document, YamlSubsetOfPyYaml) {
  using agvdyn::ff::detail::Node;
  Node root;
  std::string error;
  ASSERT_TRUE(agvdyn::ff::detail::parse_document(kIdentifyYaml, &root, &error)) << error;
  const Node* sources = root.find("sources");
  ASSERT_TRUE(sources && sources->is_sequence());
  ASSERT_EQ(sources->values.size(), 2u);
  EXPECT_EQ(sources->values[1].text, "C:\\data\\run #2.parquet");
  EXPECT_EQ(root.find("settings")->find("note")->text,
            "this is a long plain scalar that PyYAML folds over two lines because it is longer than its line width");
  EXPECT_TRUE(root.find("settings")->find("segments")->is_null());
  const Node* events = root.find("slip_events");
  ASSERT_TRUE(events && events->values.size() == 2);
  EXPECT_EQ(events->values[0].find("wheels")->values[1].text, "rl");
  EXPECT_EQ(events->values[1].find("wheels")->values[0].text, "fr");
  EXPECT_EQ(root.find("warning")->text, "a quoted string: with colon # and hash, folded over a line");
  EXPECT_TRUE(root.find("residual_rms")->is_mapping());
  double v;
  EXPECT_TRUE(root.find("condition_number")->number(&v));
  EXPECT_DOUBLE_EQ(v, 11.56);
}

TEST(PlatformFile, ReadsAPlatformFile) {
  ff::Geometry g;
  std::string name, error;
  EXPECT_TRUE(ff::read_platform_file(std::string(AGVDYN_FF_TEST_DATA) + "/data/platform.yaml", &g, &name, &error))
      << error;
  EXPECT_EQ(name, "small");
  EXPECT_DOUBLE_EQ(g.r, 0.09);
}

// --- the model beyond the paper (issue 30): the `model:` block and the extra parameters --------------
namespace {

const char* kExtendedYaml = R"(parameters:
  C_l: {value: 0.3342}
  d_vl: {value: 4.4649}
  d_cl: {value: 12.9458}
  C_r: {value: 0.4501}
  d_vr: {value: 2.482}
  d_cr: {value: 17.1071}
  m_ch: {value: 842.0684}
  C_ch: {value: 286.5955}
  d_vw: {value: 0.7316}
  d_cw: {value: 3.9656}
  B_w: {value: 0.121, fixed: true}
  d_sl: {value: 16.8, std: 0.3, unit: N m}
  d_sr: {value: 22.2, std: .inf, unit: N m}
  d_sw: {value: 5.1, std: 0.05, unit: N m}
  w_sl: {value: 0.05, unit: rad/s}
  w_sr: {value: 0.1, unit: rad/s}
  w_sw: {value: 0.02, unit: rad/s}
  x_c: {value: 0.15, std: 0.004, unit: m}
  y_c:
    value: -0.1
    std: 0.004
    unit: m
model:
  friction: stribeck
  delay: 0.006
  com_offset: true
)";

bool parse_extended(const std::string& text, ff::ParameterFile* file, std::string* error) {
  return ff::parse_parameter_file(text, "p.yaml", file, error);
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

}  // namespace

TEST(ParameterFile, ReadsAModelBlockAndItsExtraParameters) {
  ff::ParameterFile file;
  std::string error;
  ASSERT_TRUE(parse_extended(kExtendedYaml, &file, &error)) << error;
  expect_paper(file.parameters);
  ASSERT_TRUE(file.has_model);
  const ff::Extension& e = file.extension;
  EXPECT_TRUE(e.stribeck && e.com_offset);
  EXPECT_DOUBLE_EQ(e.delay_s, 0.006);
  EXPECT_DOUBLE_EQ(e.d_s[0], 16.8);
  EXPECT_DOUBLE_EQ(e.d_s[2], 5.1);
  EXPECT_DOUBLE_EQ(e.w_s[1], 0.1);
  EXPECT_DOUBLE_EQ(e.x_c, 0.15);
  EXPECT_DOUBLE_EQ(e.y_c, -0.1);
  // the paper's model: no block, or a block without extensions; extras are then not read
  ASSERT_TRUE(parse_extended(kIdentifyYaml, &file, &error)) << error;
  EXPECT_FALSE(file.has_model);
  EXPECT_FALSE(file.extension.changes_forces());
  ASSERT_TRUE(parse_extended(replaced(replaced(kExtendedYaml, "stribeck\n", "paper\n"), "com_offset: true",
                                      "com_offset: false"), &file, &error)) << error;
  EXPECT_TRUE(file.has_model);
  EXPECT_FALSE(file.extension.changes_forces());
  // JSON and the block's stribeck_velocities (what ModelSpec.to_dict writes), delay_s as in --json
  const std::string json = R"({"parameters": {"C_l": 0.3342, "d_vl": 4.4649, "d_cl": 12.9458, "C_r": 0.4501,
    "d_vr": 2.482, "d_cr": 17.1071, "m_ch": 842.0684, "C_ch": 286.5955, "d_vw": 0.7316, "d_cw": 3.9656,
    "B_w": 0.121, "d_sl": {"value": 16.8}, "d_sr": {"value": 22.2}, "d_sw": {"value": 5.1}},
    "model": {"friction": "stribeck", "delay_s": -0.002, "delay_std_s": null, "com_offset": false,
              "stribeck_velocities": [0.05, 0.1, 0.02], "stribeck_range": [0.005, 0.5]}})";
  ASSERT_TRUE(ff::parse_parameter_file(json, "p.json", &file, &error)) << error;
  EXPECT_TRUE(file.extension.stribeck && !file.extension.com_offset);
  EXPECT_DOUBLE_EQ(file.extension.w_s[2], 0.02);
  EXPECT_DOUBLE_EQ(file.extension.delay_s, -0.002);
}

TEST(ParameterFile, ModelBlockErrorsNameTheFileAndTheKey) {
  ff::ParameterFile file;
  std::string error;
  const std::string text = kExtendedYaml;
  EXPECT_FALSE(parse_extended(replaced(text, "  x_c: {value: 0.15, std: 0.004, unit: m}\n", ""), &file, &error));
  EXPECT_EQ(error, "p.yaml: model friction stribeck, com_offset: missing parameters [x_c]");
  EXPECT_FALSE(parse_extended(replaced(text, "friction: stribeck", "friction: coulomb"), &file, &error));
  EXPECT_EQ(error, "p.yaml: model.friction=coulomb: expected paper or stribeck");
  EXPECT_FALSE(parse_extended(replaced(text, "delay: 0.006", "delay: auto"), &file, &error));
  EXPECT_NE(error.find("p.yaml: model.delay=auto: expected a number of seconds"), std::string::npos) << error;
  EXPECT_FALSE(parse_extended(replaced(text, "com_offset: true", "com_offset: yes"), &file, &error));
  EXPECT_EQ(error, "p.yaml: model.com_offset=yes: expected true or false");
  EXPECT_FALSE(parse_extended(replaced(text, "delay: 0.006", "lag: 0.006"), &file, &error));
  EXPECT_NE(error.find("p.yaml: model: unknown key lag"), std::string::npos) << error;
  EXPECT_FALSE(parse_extended(replaced(text, "w_sr: {value: 0.1", "w_sr: {value: 0.0"), &file, &error));
  EXPECT_EQ(error, "p.yaml: parameter w_sr=0.000000: expected a Stribeck velocity > 0 rad/s");
  EXPECT_FALSE(parse_extended(replaced(text, "d_sw: {value: 5.1", "d_sw: {value: .nan"), &file, &error));
  EXPECT_NE(error.find("p.yaml: parameter d_sw="), std::string::npos) << error;
  EXPECT_FALSE(parse_extended(text + "  extra: 1\n", &file, &error));
  EXPECT_NE(error.find("unknown key extra"), std::string::npos) << error;
  // held: the levels the fit gave at the paper's law (ModelSpec.held), names only
  EXPECT_TRUE(parse_extended(text + "  held: [d_sl, d_sw]\n", &file, &error)) << error;
  EXPECT_FALSE(parse_extended(text + "  held: [d_cl]\n", &file, &error));
  EXPECT_EQ(error, "p.yaml: model.held: d_cl: expected a list of some of [d_sl, d_sr, d_sw]");
}

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

// The io readers on the malformed corpus (tests/data/malformed): each PLY (point cloud or mesh),
// PCD, XYZ and .conf file gives its expected error (type and message fragment), naming the file.

#include <gtest/gtest.h>

#include <set>

#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/malformed_corpus.h"

namespace scanclean {
namespace {

TEST(MalformedCorpusTest, EveryPointCloudAndConfFileGivesItsExpectedError) {
  const auto cases = test::malformed_cases({"ply_", "pcd_", "xyz_", "conf_", "mesh_"});
  ASSERT_GE(cases.size(), 40u) << "EXPECTED.tsv missing or short in " << test::malformed_dir();
  for (const auto& c : cases) {
    const auto path = test::malformed_dir() / c.file;
    ASSERT_TRUE(std::filesystem::exists(path)) << path;
    std::string type, message;
    try {
      if (path.extension() == ".conf")
        read_conf(path);
      else if (c.file.rfind("mesh_", 0) == 0)
        read_triangle_mesh(path);
      else
        read_point_cloud(path);
    } catch (const std::exception& e) {
      type = test::error_type(e);
      message = e.what();
    }
    EXPECT_EQ(type, c.type) << c.file << ": " << (message.empty() ? "no error" : message);
    EXPECT_NE(message.find(c.fragment), std::string::npos)
        << c.file << ": expected \"" << c.fragment << "\" in: " << message;
    EXPECT_NE(message.find(c.file), std::string::npos) << c.file << ": not named in: " << message;
  }
}

TEST(MalformedCorpusTest, EveryFileOfTheCorpusIsInTheTable) {
  std::set<std::string> listed;
  for (const auto& c : test::malformed_cases({""})) listed.insert(c.file);
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(test::malformed_dir())) {
    const std::string name = e.path().filename().string();
    if (name == "EXPECTED.tsv" || name == "generate.py" || name == "README.md") continue;
    ++files;
    EXPECT_TRUE(listed.count(name)) << name << " has no expected error in EXPECTED.tsv";
  }
  EXPECT_GE(files, 50u);
}

}  // namespace
}  // namespace scanclean

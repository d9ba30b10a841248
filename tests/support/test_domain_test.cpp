// The DDS test domains (support/test_domain.h): two reservations of one process differ, a domain a child process holds
// is not given to the parent, it is free again once that holder exited, and a full range fails with the reason. The
// lock files live in a folder of this test's own (not the machine's /tmp/surgsim-test-domains), so tests running
// beside it can neither take its domains nor be kept from theirs; only the per-salt helper uses the real folder.
#include "support/test_domain.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace surgsim::test {
namespace {

class TestDomain : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) / ("surgsim_test_domain_" + std::to_string(getpid()));
    std::filesystem::remove_all(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  /// A child process holding domain `start` (or the next free one) until `release()`; its domain, as it reported it.
  struct Holder {
    pid_t pid = -1;
    int domain = 0;
    int go_fd = -1;  // closed by release(): the child then exits
    void release() {
      ::close(go_fd);
      int st = 0;
      ::waitpid(pid, &st, 0);
      pid = -1;
    }
  };
  Holder hold_in_child(int start) const {
    int to_parent[2], to_child[2];
    EXPECT_EQ(::pipe(to_parent), 0);
    EXPECT_EQ(::pipe(to_child), 0);
    Holder h;
    h.pid = ::fork();
    if (h.pid == 0) {
      ::close(to_parent[0]);
      ::close(to_child[1]);
      int d = -1;
      try {
        DomainReservation r(start, dir_.string());
        d = r.domain();
        (void)!::write(to_parent[1], &d, sizeof d);
        char c;
        (void)!::read(to_child[0], &c, 1);  // until the parent closes its end
      } catch (...) {
        (void)!::write(to_parent[1], &d, sizeof d);
      }
      ::_exit(0);  // no destructor: the lock goes with the process
    }
    ::close(to_parent[1]);
    ::close(to_child[0]);
    EXPECT_EQ(::read(to_parent[0], &h.domain, sizeof h.domain), static_cast<ssize_t>(sizeof h.domain));
    ::close(to_parent[0]);
    h.go_fd = to_child[1];
    return h;
  }

  std::filesystem::path dir_;
};

TEST_F(TestDomain, TwoReservationsInOneProcessDiffer) {
  DomainReservation a(5, dir_.string());
  DomainReservation b(5, dir_.string());  // the same start: a's lock conflicts though this process holds it
  EXPECT_EQ(a.domain(), 5);
  EXPECT_EQ(b.domain(), 6);
  struct stat st {};
  ASSERT_EQ(::stat(dir_.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 01777u) << "the folder is created shared (sticky, writable by all)";
}

TEST_F(TestDomain, TheStartWrapsWithinOneTo200) {
  DomainReservation a(200, dir_.string());
  DomainReservation b(200, dir_.string());
  EXPECT_EQ(a.domain(), 200);
  EXPECT_EQ(b.domain(), 1);
}

TEST_F(TestDomain, HeldByAChildProcessIsNotGivenToTheParent) {
  Holder child = hold_in_child(7);
  ASSERT_EQ(child.domain, 7);
  EXPECT_EQ(DomainReservation::try_take(7, dir_.string()), -1);
  DomainReservation mine(7, dir_.string());
  EXPECT_EQ(mine.domain(), 8);
  child.release();
}

TEST_F(TestDomain, FreedWhenTheHolderExits) {
  Holder child = hold_in_child(9);
  ASSERT_EQ(child.domain, 9);
  EXPECT_EQ(DomainReservation::try_take(9, dir_.string()), -1);
  child.release();
  const int fd = DomainReservation::try_take(9, dir_.string());
  EXPECT_GE(fd, 0) << "domain 9 is still taken after its holder exited";
  if (fd >= 0) ::close(fd);
  EXPECT_EQ(DomainReservation(9, dir_.string()).domain(), 9);
}

TEST_F(TestDomain, AllTakenFailsWithTheReason) {
  std::vector<std::unique_ptr<DomainReservation>> all;
  for (int i = 0; i < kTestDomainCount; ++i) all.push_back(std::make_unique<DomainReservation>(1, dir_.string()));
  EXPECT_EQ(all.back()->domain(), kTestDomainCount);
  try {
    DomainReservation one_more(1, dir_.string());
    ADD_FAILURE() << "got domain " << one_more.domain() << " while all were held";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no free DDS test domain"), std::string::npos) << e.what();
  }
}

// The helper the tests call: one domain per salt for the life of the process, the same at every call.
TEST(TestDomainPerSalt, EachSaltItsOwnDomainKeptForTheProcess) {
  const int a = reserve_test_domain(3);
  const int b = reserve_test_domain(4);
  EXPECT_NE(a, b);
  EXPECT_EQ(reserve_test_domain(3), a);
  EXPECT_GE(a, 1);
  EXPECT_LE(a, kTestDomainCount);
  EXPECT_EQ(DomainReservation::try_take(a, kTestDomainDir), -1) << "this process holds it";
}

}  // namespace
}  // namespace surgsim::test

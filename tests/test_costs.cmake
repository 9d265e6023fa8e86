# Each long test's measured time (seconds, on 2 cores, the whole suite running), as CTest's COST: CTest starts the
# costliest first. It orders by its own history (build/Testing/Temporary/CTestCostData.txt) when there is one, but
# a fresh machine (CI) has none and starts tests in declaration order, so the 150 s browser test, declared near the
# end of tests/CMakeLists.txt, ran alone after everything else and set the suite's length. A name no longer
# registered is ignored. Refresh after a suite run on a loaded machine (tests over 10 s):
#   awk 'NF==3 && $3>10 {printf "  [=[%s]=] %d\n", $1, $3}' build/Testing/Temporary/CTestCostData.txt | sort -k2 -rn
set(vb_test_costs
  [=[WebBrowser.ChromiumFollowsTheLab]=] 154
  [=[Python.Package]=] 130
  [=[BenchTwin.AValveThatChangedIsNamedAsTheCauseOfTheRegressedNights]=] 92
  [=[BenchctlRemote.ImportThenDiagnoseStoredRuns]=] 82
  [=[BenchTwin.ACodeRegressionOnAnUnchangedValveIsNamedAsTheCode]=] 74
  [=[BenchTwin.AfterARebaselineTheReplayComparesWithTheBaselinesNightsValve]=] 56
  [=[Suggest.TheLoopWithBenchctlAlone]=] 49
  [=[Python.Notebooks]=] 48
  [=[Practice4.AValveWhoseRunsNoLongerDipIsNamedStuck]=] 35
  [=[TrackSessions.AResistanceStepIsFlaggedAsRAndNothingBefore]=] 34
  [=[BenchctlCli.DiagnoseReportsJsonAndRefusesBadData]=] 34
  [=[Attribution.PracticeSensorLagWithTheFullCatalog]=] 32
  [=[HeadlessReport.ComparedLawsAreOverlaidAndPagesFitALaptopScreen]=] 31
  [=[Package.InstallRunUpgradePurge]=] 25
  [=[MovingValveSynthetic.FitRunsAtTwoSuppliesJudgeTheEdgeWithTheirOwnBias]=] 25
  [=[Diagnose.NoneOnEffectFreeDataAndSignificantOtherwise]=] 23
  [=[TrackSessions.AValveNearTheHeldGapsRatioIsIdentifiedAtItsNoiseAndAWarmStartKeepsIt]=] 20
  [=[LabNights.TheClaimingHostChecksEveryLiveHostsBenches]=] 19
  [=[BenchTwin.ACodeRegressionOnAFlaggedValveIsTheCodesWhenTheBaselinesCodeDoesNotReproduceIt]=] 19
  [=[Practice3/MovingValveWithheld.NamesTheChange/"m05"]=] 18
  [=[Practice3/MovingValveWithheld.NamesTheChange/"m02"]=] 17
  [=[Practice3/MovingValveWithheld.NamesTheChange/"m06"]=] 16
  [=[Practice3/MovingValveWithheld.NamesTheChange/"m04"]=] 16
  [=[Practice3/MovingValveWithheld.NamesTheChange/"m03"]=] 16
  [=[MovingValveSynthetic.SaturatingCoreJoinsTheModelWhenDecisive]=] 15
  [=[SpoolDrill.AStoppedDatabaseNeverReachesTheLoop]=] 13
  [=[MovingValveSynthetic.APredictionFarFromItsPullInEdgeIsTrusted]=] 13
  [=[Spool.TheLoopNeverWaitsForAStoreThatDoesNotAnswer]=] 12
  [=[MovingValveSynthetic.OtherValveIdentifiedAndPredictedAtAnotherPressureAndSupply]=] 12
  [=[MovingValve.OneRunSaysNothingCanBeHeldOut]=] 12
  [=[LabDrill.DatabaseRestartAndTerminatedSessionsLoseNothing]=] 12
  [=[SpoolDrill.ALockedSQLiteStoreNeverReachesTheLoop]=] 11
  [=[HeadlessReport.BatchRunRegressionAndDiagnosisPagesRenderWithoutErrors]=] 11
  [=[WebDoorTest.ATrickledBodyIsCutOffByItsMinimumRate]=] 10
)
list(LENGTH vb_test_costs n)
math(EXPR last "${n} - 1")
foreach(k RANGE 0 ${last} 2)
  math(EXPR v "${k} + 1")
  list(GET vb_test_costs ${k} name)
  list(GET vb_test_costs ${v} cost)
  # Read twice: by CMake at configure time (tests/CMakeLists.txt sets vb_test_costs_configure), for the tests
  # registered with add_test, and by CTest (TEST_INCLUDE_FILES), for the ones gtest_discover_tests registers at
  # build time. CTest reads this before the directory's add_test lines, and ignores names it does not know.
  if(NOT vb_test_costs_configure)
    set_tests_properties("${name}" PROPERTIES COST ${cost})
  elseif(TEST "${name}")
    set_tests_properties("${name}" PROPERTIES COST ${cost})
  endif()
endforeach()

# Reference values for hapticlab's statistics, computed with R's standard packages from a
# study in the columns of hapticlab's long.csv export.
#
#   Rscript tests/r/reference.R STUDY.csv STUDY_NAME KIND OUT.csv
#
# KIND is "oneway" (one within factor, sample; optional groups), "factorial" (2x2x2
# within each block, ratings z-scored per participant and block with divisor n) or
# "crossed" (hand x texture, 2 x 3 within, raw ratings).
# Each output row carries the R call that produced its value.
suppressMessages({library(afex); library(lme4); library(car); library(ordinal); library(effectsize)})
options(contrasts = c("contr.sum", "contr.poly"), digits = 17)
a <- commandArgs(trailingOnly = TRUE)
d <- read.csv(a[1], stringsAsFactors = FALSE, na.strings = "")
study <- a[2]; kind <- a[3]
out <- list()
add <- function(analysis, term, stat, value, call) {
  out[[length(out) + 1]] <<- data.frame(study = study, analysis = analysis, term = term,
                                        stat = stat, value = value, call = call)
}
d$participant <- factor(d$participant)

# 95 % CI of partial eta^2: the noncentrality lambda with pf(F, df1, df2, lambda) = .975
# and .025, as eta^2 = lambda / (lambda + df2) (effectsize's conversion). Solved here with
# uniroot at tol 1e-12: effectsize::F_to_eta2 searches with a looser tolerance and, at
# F near 0, returns upper bounds up to 0.03 away from the root of pf (checked with pf).
np2_ci <- function(F, df1, df2) {
  bound <- function(p) {
    if (pf(F, df1, df2, ncp = 0) < p) return(0)
    hi <- 1; while (pf(F, df1, df2, ncp = hi) > p) hi <- hi * 2
    l <- uniroot(function(l) pf(F, df1, df2, ncp = l) - p, c(0, hi), tol = 1e-12)$root
    l / (l + df2)
  }
  c(bound(0.975), bound(0.025))
}
TOST_BOUND <- 0.5  # rating points (tests/analysis/test_against_r.py uses the same)
NP2_CALL <- "uniroot(pf(F, df1, df2, ncp = l) - p, tol = 1e-12), eta2 = l / (l + df2)"

if (kind == "oneway") {
  lv <- sort(unique(d$sample))
  d$sample <- factor(d$sample, levels = lv)
  cm <- aggregate(rating ~ participant + sample, data = d, FUN = mean)
  w <- reshape(cm, idvar = "participant", timevar = "sample", direction = "wide")
  w <- w[complete.cases(w), ]
  colnames(w) <- sub("^rating\\.", "", colnames(w))
  pairs <- combn(lv, 2)
  tp <- wp <- c(); keys <- c()
  for (j in seq_len(ncol(pairs))) {
    x <- w[[pairs[1, j]]]; y <- w[[pairs[2, j]]]; key <- paste(pairs[, j], collapse = "|")
    tt <- tryCatch(t.test(x, y, paired = TRUE), error = function(e) NULL)
    if (!is.null(tt)) {
      call <- "t.test(x, y, paired = TRUE)"
      add("ttest", key, "t", unname(tt$statistic), call)
      add("ttest", key, "df", unname(tt$parameter), call)
      add("ttest", key, "p", tt$p.value, call)
      add("ttest", key, "mean_diff", unname(tt$estimate), call)
      add("ttest", key, "ci_low", tt$conf.int[1], call)
      add("ttest", key, "ci_high", tt$conf.int[2], call)
      tp <- c(tp, setNames(tt$p.value, key))
      # equivalence within +-TOST_BOUND rating points: the two one-sided tests
      lo <- t.test(x, y, paired = TRUE, mu = -TOST_BOUND, alternative = "greater")
      hi <- t.test(x, y, paired = TRUE, mu = TOST_BOUND, alternative = "less")
      ci <- t.test(x, y, paired = TRUE, conf.level = 0.90)$conf.int
      call <- sprintf("max(t.test(x, y, paired = TRUE, mu = -%g, alternative = \"greater\")$p.value, t.test(x, y, paired = TRUE, mu = %g, alternative = \"less\")$p.value)", TOST_BOUND, TOST_BOUND)
      add("tost", key, "p", max(lo$p.value, hi$p.value), call)
      add("tost", key, "t_lower", unname(lo$statistic), call)
      add("tost", key, "t_upper", unname(hi$statistic), call)
      add("tost", key, "ci_low", ci[1], "t.test(x, y, paired = TRUE, conf.level = 0.90)$conf.int")
      add("tost", key, "ci_high", ci[2], "t.test(x, y, paired = TRUE, conf.level = 0.90)$conf.int")
    }
    if (any(x != y)) {
      wt <- suppressWarnings(wilcox.test(x, y, paired = TRUE, digits.rank = 7))
      call <- "wilcox.test(x, y, paired = TRUE, digits.rank = 7)"
      add("wilcoxon", key, "V", unname(wt$statistic), call)
      add("wilcoxon", key, "p", wt$p.value, call)
      wp <- c(wp, setNames(wt$p.value, key))
    }
  }
  for (k in names(tp)) {
    add("ttest", k, "p_holm", p.adjust(tp, "holm")[[k]], "p.adjust(p, \"holm\") over the t-tests")
    add("ttest", k, "p_fdr", p.adjust(tp, "BH")[[k]], "p.adjust(p, \"BH\") over the t-tests")
  }
  for (k in names(wp))
    add("wilcoxon", k, "p_holm", p.adjust(wp, "holm")[[k]],
        "p.adjust(p, \"holm\") over the Wilcoxon tests")
  fr <- friedman.test(as.matrix(w[, lv]))
  add("friedman", "sample", "Q", unname(fr$statistic), "friedman.test(as.matrix(wide))")
  add("friedman", "sample", "p", fr$p.value, "friedman.test(as.matrix(wide))")
  fit <- suppressWarnings(suppressMessages(
    aov_ez("participant", "rating", d, within = "sample", fun_aggregate = mean)))
  s <- summary(fit)
  call <- "afex::aov_ez(\"participant\", \"rating\", d, within = \"sample\", fun_aggregate = mean)"
  an <- anova(fit, correction = "none", es = "pes")
  add("anova", "sample", "F", an$F[1], call)
  add("anova", "sample", "DF_err", an$`den Df`[1], call)
  add("anova", "sample", "p_unc", an$`Pr(>F)`[1], call)
  add("anova", "sample", "np2", an$pes[1], call)
  ci <- np2_ci(an$F[1], an$`num Df`[1], an$`den Df`[1])
  add("anova", "sample", "np2_ci_low", ci[1], NP2_CALL)
  add("anova", "sample", "np2_ci_high", ci[2], NP2_CALL)
  add("anova", "sample", "eps_gg", s$pval.adjustments[1, "GG eps"], paste("summary of", call))
  add("anova", "sample", "p_gg", s$pval.adjustments[1, "Pr(>F[GG])"], paste("summary of", call))
  add("anova", "sample", "eps_hf", min(1, s$pval.adjustments[1, "HF eps"]),
      paste("min(1, HF eps), summary of", call))
  add("anova", "sample", "W_mauchly", s$sphericity.tests[1, "Test statistic"],
      paste("summary of", call))
  add("anova", "sample", "p_spher", s$sphericity.tests[1, "p-value"], paste("summary of", call))
  m <- lmer(rating ~ sample + (1 | participant), data = d, REML = TRUE)
  call <- "car::Anova(lmer(rating ~ sample + (1 | participant)), type = 3)"
  ch <- Anova(m, type = 3, test.statistic = "Chisq")
  add("mixed", "sample", "chi2", ch["sample", "Chisq"], call)
  add("mixed", "sample", "p", ch["sample", "Pr(>Chisq)"], call)
  vc <- as.data.frame(VarCorr(m))
  add("mixed", "sample", "sd_subject", vc$sdcor[vc$grp == "participant"], "VarCorr(lmer(...))")
  add("mixed", "sample", "sd_resid", vc$sdcor[vc$grp == "Residual"], "VarCorr(lmer(...))")
  d$r <- factor(d$rating, ordered = TRUE)
  tr <- list(sample = "contr.treatment")
  o1 <- clmm(r ~ sample + (1 | participant), data = d, nAGQ = 20, contrasts = tr)
  o0 <- clmm(r ~ 1 + (1 | participant), data = d, nAGQ = 20)
  call <- "ordinal::clmm(ordered(rating) ~ sample + (1 | participant), nAGQ = 20)"
  add("ordinal", "sample", "lr", 2 * (as.numeric(logLik(o1)) - as.numeric(logLik(o0))),
      paste("2 x logLik difference of", call, "and of ~ 1 + (1 | participant)"))
  add("ordinal", "sample", "loglik", as.numeric(logLik(o1)), call)
  add("ordinal", "sample", "sd_subject", sqrt(VarCorr(o1)$participant[1]), call)
  cf <- coef(summary(o1))
  for (t in rownames(cf)) {
    key <- sub("^sample", "", t)
    add("ordinal_coef", key, "estimate", cf[t, "Estimate"], paste("coef(summary(", call, "))"))
    add("ordinal_coef", key, "se", cf[t, "Std. Error"], paste("coef(summary(", call, "))"))
  }
  if (length(unique(na.omit(d$group))) >= 2) {
    d$group <- factor(d$group)
    m <- lmer(rating ~ sample * group + (1 | participant), data = d, REML = TRUE)
    call <- "car::Anova(lmer(rating ~ sample * group + (1 | participant)), type = 3), contr.sum"
    ch <- Anova(m, type = 3, test.statistic = "Chisq")
    for (t in c("sample", "group", "sample:group")) {
      add("mixed_group", t, "chi2", ch[t, "Chisq"], call)
      add("mixed_group", t, "p", ch[t, "Pr(>Chisq)"], call)
    }
  }
} else if (kind == "crossed") {
  d$hand <- factor(d$hand, levels = c("left", "right"))
  d$texture <- factor(d$texture, levels = c("smooth", "ridged", "coarse"))
  fit <- suppressWarnings(suppressMessages(
    aov_ez("participant", "rating", d, within = c("hand", "texture"), fun_aggregate = mean)))
  an <- anova(fit, correction = "none", es = "pes")
  s <- summary(fit)
  call <- "afex::aov_ez(\"participant\", \"rating\", d, within = c(\"hand\", \"texture\"))"
  for (t in rownames(an)) {
    key <- gsub(":", " * ", t)
    add("crossed", key, "F", an[t, "F"], call)
    add("crossed", key, "p_unc", an[t, "Pr(>F)"], call)
    add("crossed", key, "np2", an[t, "pes"], call)
    if (t %in% rownames(s$pval.adjustments)) {
      add("crossed", key, "eps_gg", s$pval.adjustments[t, "GG eps"], paste("summary of", call))
      add("crossed", key, "p_gg", s$pval.adjustments[t, "Pr(>F[GG])"], paste("summary of", call))
      add("crossed", key, "eps_hf", min(1, s$pval.adjustments[t, "HF eps"]),
          paste("min(1, HF eps), summary of", call))
      add("crossed", key, "W_mauchly", s$sphericity.tests[t, "Test statistic"],
          paste("summary of", call))
      add("crossed", key, "p_spher", s$sphericity.tests[t, "p-value"], paste("summary of", call))
    }
  }
} else {
  f <- c("frequency", "decay", "slope")
  for (x in f) d[[x]] <- factor(d[[x]], levels = c("low", "high"))
  for (b in unique(d$block)) {
    g <- d[d$block == b, ]
    # a participant who rated every set of the block the same has no z-scores: left out
    flat <- ave(g$rating, g$participant, FUN = function(x) max(x) - min(x)) == 0
    g <- droplevels(g[!flat, ])
    g$rating_z <- ave(g$rating, g$participant, FUN = function(x)
      (x - mean(x)) / sqrt(mean((x - mean(x))^2)))
    fit <- suppressWarnings(suppressMessages(
      aov_ez("participant", "rating_z", g, within = f, fun_aggregate = mean)))
    an <- anova(fit, correction = "none", es = "pes")
    call <- paste0("afex::aov_ez(\"participant\", \"rating_z\", block ", b,
                   ", within = c(\"frequency\", \"decay\", \"slope\")); z = (x - mean) / sd with divisor n; constant participants left out")
    for (t in rownames(an)) {
      key <- paste(b, gsub(":", " * ", t), sep = "|")
      add("factorial", key, "F", an[t, "F"], call)
      add("factorial", key, "p_unc", an[t, "Pr(>F)"], call)
      add("factorial", key, "np2", an[t, "pes"], call)
      ci <- np2_ci(an[t, "F"], an[t, "num Df"], an[t, "den Df"])
      add("factorial", key, "np2_ci_low", ci[1], NP2_CALL)
      add("factorial", key, "np2_ci_high", ci[2], NP2_CALL)
    }
  }
}
res <- do.call(rbind, out)
res$value <- sprintf("%.17g", res$value)  # every digit R computed
write.csv(res, a[4], row.names = FALSE)
